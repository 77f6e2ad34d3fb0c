#!/usr/bin/env bash
# Redraws the README's gallery images in docs/ from a demo's packs: the gallery's start view and
# close-up (as `digitize demo` writes them), and one picture per style (its start view beside
# its close-up). Usage: tools/readme_images.sh [DEMO_FOLDER] (default: a fresh demo in a
# temporary folder). Needs the build (tools/dev.sh build) and oiiotool (openimageio-tools).
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
demo=${1:-}
if [ -z "$demo" ]; then
  work=$(mktemp -d)
  trap 'rm -rf "$work"' EXIT
  (cd "$work" && "$root/build/bin/digitize" demo > demo.log)
  demo=$work/digitize-demo
fi
packs=("$demo/painting.pack.exr" "$demo/rti.pack.exr")
shots=$(mktemp -d)
cp "$demo/gallery.png" "$root/docs/viewer_gallery.png"
oiiotool "$demo/gallery_closeup.png" --compression jpeg:88 -o "$root/docs/viewer_gallery_closeup.jpg"
for style in watercolor binary collage hatching painterly; do
  "$root/build/bin/digitize-viewer" "${packs[@]}" --style "$style" --size 1280x720 \
    --screenshot "$shots/$style.png" --close-up "$shots/${style}_near.png" > /dev/null
  oiiotool "$shots/$style.png" --resize 640x360 "$shots/${style}_near.png" --resize 640x360 \
    --mosaic:pad=4 2x1 --compression jpeg:88 -o "$root/docs/style_$style.jpg"
  echo "wrote docs/style_$style.jpg"
done
rm -rf "$shots"
