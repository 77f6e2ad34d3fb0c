# The files of each library layer (docs/architecture.md), relative to libdigitize/include/digitize
# (headers) and libdigitize/src (sources). Adding a file to a layer: one line here. Read by
# libdigitize/CMakeLists.txt (one target per layer) and tests/fuzz/CMakeLists.txt (which compiles
# the parser layers again, instrumented).

set(DIGITIZE_CORE_HEADERS core.h height_field.h scan_data.h)
set(DIGITIZE_CORE_SOURCES)

set(DIGITIZE_IO_HEADERS image_io.h scan_io.h output_dir.h)
set(DIGITIZE_IO_SOURCES
  image_io.cpp    # OpenImageIO
  output_dir.cpp
  scan_io.cpp     # OpenMesh (PLY)
  json_fields.cpp # the one JSON field reader (private json_fields.h)
  transform_json.cpp  # RigidTransform to and from JSON
)

set(DIGITIZE_CANVAS_HEADERS scan.h canvas.h resample.h scan_registration.h)
set(DIGITIZE_CANVAS_SOURCES
  scan.cpp
  canvas.cpp           # ExtractCanvas: the driver over the steps below
  canvas_plane.cpp     # PCA and robust canvas plane, noise estimate
  canvas_region.cpp    # region growing from a seed
  canvas_boundary.cpp  # boundary refinement to the frame step
  canvas_outline.cpp   # OpenCV calib3d (homography, minimum-area rectangle): the outline rectangle
  canvas_frame.cpp     # the frame's boxes from the scan points around the outline
  resample.cpp         # ResampleToCanvasGrid: the driver and rasterisation
  resample_holes.cpp   # hole filling, texel states
  mask_ops.cpp    # OpenCV morphology shared by canvas.cpp and resample.cpp
  scan_registration.cpp  # overlapping patches: phase correlation, OpenCV contrib ICP, merge
)

set(DIGITIZE_RELIEF_HEADERS relief.h normals.h photometric_stereo.h normal_integration.h
  sphere_calibration.h)
set(DIGITIZE_RELIEF_SOURCES
  relief.cpp      # OpenCV connected components
  normals.cpp
  photometric_stereo.cpp  # robust per-pixel normals, albedo and light intensities
  normal_integration.cpp  # height from normals: Eigen sparse Poisson, OpenCV DFT Frankot-Chellappa
  sphere_calibration.cpp  # OpenCV HoughCircles: light directions from a reflective sphere
)

set(DIGITIZE_PREPROCESS_HEADERS preprocess.h preprocess_tiled.h)
set(DIGITIZE_PREPROCESS_SOURCES
  preprocess.cpp
  preprocess_patches.cpp  # PreprocessPatches, the patch list and the registration report
  preprocess_tiled.cpp    # one scan too large to hold: the canvas strided, then tiles
                          # (private preprocess_internal.h: what both share)
)

set(DIGITIZE_PHOTOS_HEADERS photo_set.h photo_tile_cache.h rti_basis.h rti_export.h)
set(DIGITIZE_PHOTOS_SOURCES
  photo_calibration.cpp  # calibration JSON: transforms, cameras, lights
  rti_lp.cpp             # RTI .lp light files
  photo_pixels.cpp       # image headers, pixels, colour
  photo_checks.cpp       # camera, light and footprint checks
  photo_tile_cache.cpp   # tiled copies of PNG / JPEG photos for the tile jobs
  rti_basis.cpp          # PTM / HSH per-pixel fits, relighting, 8-bit sRGB PSNR
  rti_export.cpp         # .ptm (RTIViewer) and relight's info.json + plane_N.jpg (OpenLIME)
)

set(DIGITIZE_BRDF_HEADERS lafortune.h ggx.h brdf_fit.h tangent_frame.h reflectance_maps.h)
set(DIGITIZE_BRDF_SOURCES
  lafortune.cpp
  reflectance_maps.cpp
  brdf_fit.cpp         # front end: per-texel problem, solver choice, the tiled loop
  brdf_fit_varpro.cpp  # the fast variable-projection solver
  brdf_fit_ceres.cpp   # Ceres: the ceres::Solve reference (the one file that includes Ceres)
)

set(DIGITIZE_SAMPLES_HEADERS height_field_tracer.h relight.h reflectance_samples.h reflectance_fit.h
  photo_residuals.h)
set(DIGITIZE_SAMPLES_SOURCES
  height_field_tracer.cpp  # Embree
  relight.cpp
  reflectance_samples.cpp
  shadow_horizon.cpp  # per-texel horizon bounds: rays proven free without the tracer
  reflectance_fit.cpp
  photo_residuals.cpp  # OpenCV (phase correlation): per-photo gain and misregistration
)

set(DIGITIZE_PACK_HEADERS pack.h pack_pyramid.h pack_tiled.h provenance.h)
set(DIGITIZE_PACK_SOURCES
  pack.cpp         # the model, its validation and encodings
  pack_write.cpp   # OpenImageIO: WritePack (multi-part OpenEXR)
  pack_pyramid.cpp # the 2 x 2 prefilter of a coarser level (Toksvig)
  pack_tiled.cpp   # OpenEXR: WriteTiledPack (version 3: tiled, mip-mapped, streamed by bands)
  pack_read.cpp    # OpenImageIO: the bounded reader (header pre-scan, ReadPack, InspectPack, tiles)
  pack_verify.cpp  # VerifyPack (SHA-1 of the pixels)
  provenance.cpp   # where a pack came from, and its JSON form
)

set(DIGITIZE_PIPELINE_HEADERS pipeline.h rti_canvas.h tile_plan.h tile_jobs.h)
set(DIGITIZE_PIPELINE_SOURCES
  pipeline.cpp     # scan -> canvas -> fit -> pack, as the commands run it
  rti_canvas.cpp   # an RTI capture -> intensities, normals, height, relief
  tile_plan.cpp    # a painting's fit cut into tiles: the job plan
  tile_jobs.cpp    # running, merging a tile plan; its Slurm scripts
)
