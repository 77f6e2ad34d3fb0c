// Streaming a tiled pack's pyramid (pyramid_stream.h).
#include "digitize_viewer/pyramid_stream.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <map>
#include <mutex>
#include <optional>
#include <set>
#include <thread>

#include "digitize/pack_tiled.h"
#include "digitize_viewer/painting_setup.h"

namespace digitize::viewer {

namespace fs = std::filesystem;

Status StreamOptions::Validate() const {
  if (!(std::isfinite(max_texel_px) && max_texel_px > 0))
    return Error{"stream: max_texel_px must be finite and > 0"};
  if (budget_bytes < (int64_t{1} << 20)) return Error{"stream: the GPU budget must be >= 1 MB"};
  if (max_uploads_per_frame < 1) return Error{"stream: max_uploads_per_frame must be >= 1"};
  if (max_decoded < 1) return Error{"stream: max_decoded must be >= 1"};
  if (loader_threads < 1 || loader_threads > 16)
    return Error{"stream: loader_threads must be in [1, 16]"};
  return Status::Ok();
}

namespace {

// A tile's texels as the GPU takes them (pyramid_stream.h, GpuTile), with an apron of one texel
// from each neighbour of its level there is (`around[dy + 1][dx + 1]`, the tile at [1][1]): so
// the bilinear normals and heights are continuous across tile edges.
GpuTile ToGpuTile(const std::array<std::array<const PackTile*, 3>, 3>& around, int tile_size) {
  const PackTile& tile = *around[1][1];
  GpuTile g;
  g.key = {tile.level, tile.tile_x, tile.tile_y};
  g.own_x0 = tile.x0;
  g.own_y0 = tile.y0;
  g.own_width = tile.texels.field.width();
  g.own_height = tile.texels.field.height();
  const int left = around[1][0] ? 1 : 0, right = around[1][2] ? 1 : 0;
  const int top = around[0][1] ? 1 : 0, bottom = around[2][1] ? 1 : 0;
  g.x0 = tile.x0 - left;
  g.y0 = tile.y0 - top;
  g.width = g.own_width + left + right;
  g.height = g.own_height + top + bottom;
  g.pitch_mm = tile.texels.field.pitch_mm;
  // Texel (x, y) of the texture: its tile and the texel there (no tile where a corner neighbour
  // is missing: the nearest edge texel of the tile itself).
  const auto source = [&](int x, int y) -> std::pair<const PackLevel*, int> {
    int lx = g.x0 + x - tile.x0, ly = g.y0 + y - tile.y0;
    const int dx = lx < 0 ? -1 : lx >= g.own_width ? 1 : 0;
    const int dy = ly < 0 ? -1 : ly >= g.own_height ? 1 : 0;
    const PackTile* t = around[dy + 1][dx + 1];
    if (t == nullptr) {
      t = &tile;
      lx = std::clamp(lx, 0, g.own_width - 1);
      ly = std::clamp(ly, 0, g.own_height - 1);
    } else {
      lx -= dx * (dx < 0 ? t->texels.field.width() : tile_size);
      ly -= dy * (dy < 0 ? t->texels.field.height() : tile_size);
    }
    return {&t->texels, ly * t->texels.field.width() + lx};
  };
  // ShadingSource reads the grid's states and statuses only.
  Pack grid;
  grid.field.state = Grid<TexelState>(g.width, g.height, TexelState::kOutside);
  grid.field.height_mm = Grid<float>(g.width, g.height, 0.0f);
  grid.maps.status = Grid<TexelFitStatus>(g.width, g.height, TexelFitStatus::kTooFewSamples);
  for (int y = 0; y < g.height; ++y)
    for (int x = 0; x < g.width; ++x) {
      const auto [t, i] = source(x, y);
      grid.field.state(x, y) = t->field.state.data[i];
      grid.maps.status(x, y) = t->maps.status.data[i];
    }
  const std::vector<size_t> shading = ShadingSource(grid);
  const size_t n = size_t(g.width) * g.height;
  for (auto& v : g.rgba) v.resize(4 * n);
  float lo = INFINITY, hi = -INFINITY;
  for (size_t i = 0; i < n; ++i) {
    const bool shaded = shading[i] != SIZE_MAX;
    const auto [t, at] = source(int(i % g.width), int(i / g.width));
    const auto [ts, from] =
        shaded ? source(int(shading[i] % g.width), int(shading[i] / g.width)) : std::pair{t, at};
    const float h = t->field.height_mm.data[at];
    lo = std::min(lo, h);
    hi = std::max(hi, h);
    for (int k = 0; k < 3; ++k) {
      g.rgba[0][4 * i + k] = t->normals.data[at][k];
      g.rgba[1][4 * i + k] = ts->maps.rho_d.data[from][k];
      g.rgba[2][4 * i + k] = ts->maps.rho_s.data[from][k];
    }
    g.rgba[0][4 * i + 3] = h;
    g.rgba[1][4 * i + 3] = shaded ? 1.0f : 0.0f;
    g.rgba[2][4 * i + 3] = float(static_cast<int>(ts->maps.model.data[from]));
    for (int k = 0; k < 4; ++k) g.rgba[3][4 * i + k] = ts->maps.lobe.data[from][k];
  }
  g.min_height_mm = n > 0 ? lo : 0.0f;
  g.max_height_mm = n > 0 ? hi : 0.0f;
  return g;
}

struct Resident {
  int64_t bytes = 0;
  uint64_t last_drawn = 0;
};

}  // namespace

struct PyramidStream::Impl {
  fs::path path;
  StreamOptions options;
  std::unique_ptr<TiledPackReader> reader;
  PackSummary summary;
  int root = 0;
  double width_mm = 0, height_mm = 0;
  double min_height_mm = 0, max_height_mm = 0;  // the boxes' z range for selection
  std::optional<GpuTile> root_tile;             // until the first frame hands it over

  // Main thread only.
  std::map<TileKey, Resident> resident;
  uint64_t frame = 0;
  int64_t resident_bytes = 0;

  // Shared with the loaders.
  std::mutex mutex;
  std::condition_variable wake, idle;
  std::deque<TileKey> queue;
  std::set<TileKey> in_flight;
  std::map<TileKey, GpuTile> decoded;
  std::set<TileKey> failed;
  std::vector<std::string> new_errors;
  bool stop = false;
  std::vector<std::thread> loaders;

  void Loader() {
    std::unique_lock lock(mutex);
    for (;;) {
      wake.wait(lock, [&] {
        return stop ||
               (!queue.empty() && int(decoded.size() + in_flight.size()) < options.max_decoded);
      });
      if (stop) return;
      const TileKey key = queue.front();
      queue.pop_front();
      in_flight.insert(key);
      lock.unlock();
      auto tile = Read(key);
      lock.lock();
      in_flight.erase(key);
      if (tile.ok()) {
        decoded.emplace(key, std::move(tile).value());
      } else {
        failed.insert(key);
        new_errors.push_back(tile.error().message);  // the reader's errors name the file
      }
      idle.notify_all();
    }
  }

  // Decoded tiles, kept for their neighbours' aprons (a tile's apron reads up to 8 of them).
  std::mutex cache_mutex;
  std::map<TileKey, std::pair<std::shared_ptr<const PackTile>, uint64_t>> cache;
  uint64_t cache_clock = 0;
  // Enough for both loaders' 3 x 3 neighbourhoods: ~100 MB of decoded 256^2 tiles at most.
  static constexpr size_t kCacheTiles = 24;

  Result<std::shared_ptr<const PackTile>> Fetch(const TileKey& k) {
    {
      std::lock_guard lock(cache_mutex);
      if (auto it = cache.find(k); it != cache.end()) {
        it->second.second = ++cache_clock;
        return it->second.first;
      }
    }
    auto tile = reader->ReadTile(k.level, k.tx, k.ty);
    if (!tile.ok()) return tile.error();
    auto shared = std::make_shared<const PackTile>(std::move(tile).value());
    std::lock_guard lock(cache_mutex);
    cache[k] = {shared, ++cache_clock};
    while (cache.size() > kCacheTiles) {
      auto oldest = cache.begin();
      for (auto it = cache.begin(); it != cache.end(); ++it)
        if (it->second.second < oldest->second.second) oldest = it;
      cache.erase(oldest);
    }
    return shared;
  }

  // Tile k for the GPU, with its apron.
  Result<GpuTile> Read(const TileKey& k) {
    std::array<std::array<std::shared_ptr<const PackTile>, 3>, 3> held;
    std::array<std::array<const PackTile*, 3>, 3> around{};
    const auto [nx, ny] = Tiles(k.level);
    for (int dy = -1; dy <= 1; ++dy)
      for (int dx = -1; dx <= 1; ++dx) {
        const int tx = k.tx + dx, ty = k.ty + dy;
        if (tx < 0 || ty < 0 || tx >= nx || ty >= ny) continue;
        auto t = Fetch({k.level, tx, ty});
        if (!t.ok()) {
          if (dx == 0 && dy == 0) return t.error();
          continue;  // a neighbour that fails its checks: the edge clamped there instead
        }
        held[dy + 1][dx + 1] = *t;
        around[dy + 1][dx + 1] = t->get();
      }
    return ToGpuTile(around, summary.tile_size);
  }

  std::array<int, 2> Size(int level) const {
    return {int(summary.levels[level][0]), int(summary.levels[level][1])};
  }
  std::array<int, 2> Tiles(int level) const {
    const auto [w, h] = Size(level);
    const int t = summary.tile_size;
    return {(w + t - 1) / t, (h + t - 1) / t};
  }

  // The tile's box in the canvas frame (mm): x right, y up from the canvas's bottom edge.
  void Box(const TileKey& k, Vec3d& lo, Vec3d& hi) const {
    const double p = summary.pitch_mm * std::ldexp(1.0, k.level);
    const int t = summary.tile_size;
    const auto [w, h] = Size(k.level);
    const double x0 = k.tx * t * p, x1 = std::min(k.tx * t + t, w) * p;
    const double r0 = k.ty * t * p, r1 = std::min(k.ty * t + t, h) * p;
    lo = Vec3d(x0, height_mm - std::min(r1, height_mm), min_height_mm);
    hi = Vec3d(std::min(x1, width_mm), height_mm - r0, max_height_mm);
  }

  struct View {
    Camera camera;
    Vec3d eye_canvas;
    RigidTransform camera_from_canvas;
    double near_mm = 1;
  };
  View MakeView(const ViewCamera& camera, const RigidTransform& world_from_canvas) const {
    View v;
    v.camera = ToCamera(camera);
    v.camera_from_canvas = v.camera.camera_from_scan * world_from_canvas;
    v.eye_canvas = world_from_canvas.Inverse().Apply(camera.eye_mm);
    v.near_mm = camera.near_mm;
    return v;
  }

  // Whether the box is outside the view frustum (all corners beyond one side).
  bool Culled(const View& v, const Vec3d& lo, const Vec3d& hi) const {
    const double sx = (v.camera.cx + 0.5) / v.camera.fx, sy = (v.camera.cy + 0.5) / v.camera.fy;
    int out[5] = {0, 0, 0, 0, 0};
    for (int c = 0; c < 8; ++c) {
      const Vec3d corner((c & 1) ? hi.x() : lo.x(), (c & 2) ? hi.y() : lo.y(),
                         (c & 4) ? hi.z() : lo.z());
      const Vec3d q = v.camera_from_canvas.Apply(corner);
      out[0] += q.z() < v.near_mm;
      out[1] += q.x() > sx * q.z();
      out[2] += q.x() < -sx * q.z();
      out[3] += q.y() > sy * q.z();
      out[4] += q.y() < -sy * q.z();
    }
    return std::any_of(std::begin(out), std::end(out), [](int n) { return n == 8; });
  }

  // Distance from the eye to the box (0 inside), and whether a texel of the tile's level covers
  // more than max_texel_px there.
  double Distance(const View& v, const Vec3d& lo, const Vec3d& hi) const {
    const Vec3d nearest = v.eye_canvas.cwiseMax(lo).cwiseMin(hi);
    return (nearest - v.eye_canvas).norm();
  }
  bool Refine(const View& v, const TileKey& k, double distance) const {
    if (k.level == 0) return false;
    const double texel_mm = summary.pitch_mm * std::ldexp(1.0, k.level);
    return texel_mm * v.camera.fy / std::max(distance, v.near_mm) > options.max_texel_px;
  }

  std::vector<TileKey> Children(const TileKey& k) const {
    std::vector<TileKey> c;
    const auto [nx, ny] = Tiles(k.level - 1);
    for (int dy = 0; dy < 2; ++dy)
      for (int dx = 0; dx < 2; ++dx)
        if (2 * k.tx + dx < nx && 2 * k.ty + dy < ny)
          c.push_back({k.level - 1, 2 * k.tx + dx, 2 * k.ty + dy});
    return c;
  }

  // The needed tiles under k (with their distances), selection only.
  void Select(const View& v, const TileKey& k, std::vector<std::pair<double, TileKey>>& out) const {
    Vec3d lo, hi;
    Box(k, lo, hi);
    if (Culled(v, lo, hi)) return;
    const double d = Distance(v, lo, hi);
    if (!Refine(v, k, d)) {
      out.push_back({d, k});
      return;
    }
    for (const TileKey& c : Children(k)) Select(v, c, out);
  }

  // Draws k's region from resident tiles; false where some of it could not be covered (the caller
  // draws an ancestor). Needed tiles that are not resident go into `requests`.
  bool Cover(const View& v, const TileKey& k, std::vector<TileKey>& draw,
             std::vector<std::pair<double, TileKey>>& requests, int& needed) {
    Vec3d lo, hi;
    Box(k, lo, hi);
    if (Culled(v, lo, hi)) return true;
    const double d = Distance(v, lo, hi);
    const bool here = resident.count(k) > 0;
    if (!Refine(v, k, d)) {
      ++needed;
      if (here) {
        draw.push_back(k);
        return true;
      }
      requests.push_back({d, k});
      return false;
    }
    std::vector<TileKey> below;
    bool all = true;
    for (const TileKey& c : Children(k)) all = Cover(v, c, below, requests, needed) && all;
    if (all) {
      draw.insert(draw.end(), below.begin(), below.end());
      return true;
    }
    if (!here) return false;
    draw.push_back(k);
    return true;
  }
};

PyramidStream::PyramidStream(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

PyramidStream::~PyramidStream() {
  {
    std::lock_guard lock(impl_->mutex);
    impl_->stop = true;
  }
  impl_->wake.notify_all();
  for (std::thread& t : impl_->loaders) t.join();
}

Result<std::unique_ptr<PyramidStream>> PyramidStream::Open(const fs::path& path,
                                                           const StreamOptions& options) {
  if (Status s = options.Validate(); !s.ok()) return Error{path.string() + ": " + s.message()};
  auto reader = TiledPackReader::Open(path);
  if (!reader.ok()) return reader.error();
  auto impl = std::make_unique<Impl>();
  impl->path = path;
  impl->options = options;
  impl->reader = std::move(reader).value();
  impl->summary = impl->reader->summary();
  const PackSummary& s = impl->summary;
  if (s.tile_size <= 0 || s.levels.empty())
    return Error{path.string() + ": not a tiled pack (version 3): load it whole"};
  impl->width_mm = s.width * s.pitch_mm;
  impl->height_mm = s.height * s.pitch_mm;
  impl->root = int(s.levels.size()) - 1;
  while (impl->root > 0 && impl->Tiles(impl->root - 1) == std::array<int, 2>{1, 1}) --impl->root;
  auto root = impl->Read({impl->root, 0, 0});
  if (!root.ok()) return Error{path.string() + ": " + root.error().message};
  impl->root_tile = std::move(root).value();
  // The boxes reach from the lowest height of the root (an average: widened by a margin of the
  // highest) to H; selection only needs them roughly.
  impl->max_height_mm = std::max<double>(s.max_height_mm, impl->root_tile->max_height_mm);
  impl->min_height_mm =
      std::min<double>(0.0, impl->root_tile->min_height_mm) - 0.5 * std::abs(impl->max_height_mm);
  for (int i = 0; i < options.loader_threads; ++i)
    impl->loaders.emplace_back([p = impl.get()] { p->Loader(); });
  return std::unique_ptr<PyramidStream>(new PyramidStream(std::move(impl)));
}

const PackSummary& PyramidStream::summary() const { return impl_->summary; }
double PyramidStream::width_mm() const { return impl_->width_mm; }
double PyramidStream::height_mm() const { return impl_->height_mm; }
int PyramidStream::root_level() const { return impl_->root; }
std::array<int, 2> PyramidStream::LevelSize(int level) const { return impl_->Size(level); }
std::array<int, 2> PyramidStream::LevelTiles(int level) const { return impl_->Tiles(level); }

std::vector<TileKey> PyramidStream::Needed(const ViewCamera& camera,
                                           const RigidTransform& world_from_canvas) const {
  std::vector<std::pair<double, TileKey>> out;
  impl_->Select(impl_->MakeView(camera, world_from_canvas),
                {int(impl_->summary.levels.size()) - 1, 0, 0}, out);
  std::vector<TileKey> keys;
  for (const auto& [d, k] : out) keys.push_back(k);
  return keys;
}

StreamFrame PyramidStream::Frame(const ViewCamera& camera,
                                 const RigidTransform& world_from_canvas) {
  Impl& m = *impl_;
  StreamFrame f;
  ++m.frame;
  if (m.root_tile) {  // the first frame: the root, read by Open
    const TileKey root = m.root_tile->key;
    m.resident[root] = {m.root_tile->Bytes(), m.frame};
    m.resident_bytes += m.root_tile->Bytes();
    f.upload.push_back(std::move(*m.root_tile));
    m.root_tile.reset();
  }
  const Impl::View view = m.MakeView(camera, world_from_canvas);
  std::vector<std::pair<double, TileKey>> requests;
  // From the coarsest level (one texel): far views need levels coarser than the root.
  const int top = int(m.summary.levels.size()) - 1;
  if (!m.Cover(view, {top, 0, 0}, f.draw, requests, f.needed)) f.draw.push_back({m.root, 0, 0});
  for (const TileKey& k : f.draw) m.resident[k].last_drawn = m.frame;
  f.missing = int(requests.size());
  std::sort(requests.begin(), requests.end());  // nearest first
  const std::set<TileKey> drawn(f.draw.begin(), f.draw.end());
  std::set<TileKey> wanted;
  for (const auto& [d, k] : requests) wanted.insert(k);

  std::vector<GpuTile> ready;
  {
    std::lock_guard lock(m.mutex);
    // Decoded tiles this view no longer needs are dropped; the queue becomes this frame's needs.
    for (auto it = m.decoded.begin(); it != m.decoded.end();) {
      if (wanted.count(it->first) && int(ready.size()) < m.options.max_uploads_per_frame) {
        ready.push_back(std::move(it->second));
        it = m.decoded.erase(it);
      } else if (!wanted.count(it->first)) {
        it = m.decoded.erase(it);
      } else {
        ++it;
      }
    }
    m.queue.clear();
    for (const auto& [d, k] : requests)
      if (!m.in_flight.count(k) && !m.decoded.count(k) && !m.failed.count(k) &&
          std::none_of(ready.begin(), ready.end(), [&](const GpuTile& g) { return g.key == k; }))
        m.queue.push_back(k);
    f.loading = int(m.queue.size() + m.in_flight.size() + m.decoded.size());
    f.errors = std::move(m.new_errors);
    m.new_errors.clear();
  }
  m.wake.notify_all();

  // Each upload fits the budget by evicting the least recently drawn tiles not drawn now; what
  // does not fit (the tiles drawn fill it) waits, decoded, for a frame that needs fewer.
  size_t uploaded = 0;
  for (GpuTile& g : ready) {
    const int64_t bytes = g.Bytes();
    while (m.resident_bytes + bytes > m.options.budget_bytes) {
      auto victim = m.resident.end();
      for (auto it = m.resident.begin(); it != m.resident.end(); ++it) {
        if (drawn.count(it->first) || it->first == TileKey{m.root, 0, 0}) continue;
        if (victim == m.resident.end() || it->second.last_drawn < victim->second.last_drawn)
          victim = it;
      }
      if (victim == m.resident.end()) break;
      m.resident_bytes -= victim->second.bytes;
      f.evict.push_back(victim->first);
      m.resident.erase(victim);
    }
    if (m.resident_bytes + bytes > m.options.budget_bytes) break;
    m.resident[g.key] = {bytes, m.frame};
    m.resident_bytes += bytes;
    f.upload.push_back(std::move(g));
    ++uploaded;
  }
  if (uploaded < ready.size()) {
    std::lock_guard lock(m.mutex);
    for (size_t i = uploaded; i < ready.size(); ++i)
      m.decoded.emplace(ready[i].key, std::move(ready[i]));
  }
  f.resident_bytes = m.resident_bytes;
  if (!f.upload.empty()) {  // what was just uploaded is drawn now
    f.draw.clear();
    requests.clear();
    f.needed = 0;
    if (!m.Cover(view, {top, 0, 0}, f.draw, requests, f.needed)) f.draw.push_back({m.root, 0, 0});
    for (const TileKey& k : f.draw) m.resident[k].last_drawn = m.frame;
    f.missing = int(requests.size());
  }
  return f;
}

bool PyramidStream::WaitForLoads(double seconds) {
  Impl& m = *impl_;
  std::unique_lock lock(m.mutex);
  return m.idle.wait_for(lock, std::chrono::duration<double>(seconds), [&] {
    return (m.queue.empty() && m.in_flight.empty()) ||
           int(m.decoded.size()) >= m.options.max_decoded;
  });
}

}  // namespace digitize::viewer
