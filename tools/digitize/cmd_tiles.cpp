// `digitize tiles plan|run|status|merge|sbatch`: a painting's fit in tiles, on one machine or as
// Slurm jobs (tile_plan.h, tile_jobs.h, docs/cluster.md).
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <climits>
#include <cstdio>
#include <memory>

#include "commands.h"
#include "digitize/image_io.h"
#include "digitize/tile_jobs.h"
#include "digitize/tile_plan.h"
#include "progress_bar.h"

namespace digitize::cli {
namespace {

// This executable's absolute path: what the job scripts run.
std::string SelfPath() {
  char buffer[PATH_MAX];
  const ssize_t n = readlink("/proc/self/exe", buffer, sizeof buffer - 1);
  if (n <= 0) return "";
  buffer[n] = '\0';
  return buffer;
}

// bash SCRIPT, waited for: its exit status (-1 when it could not start). No shell parses the path.
int RunBash(const std::filesystem::path& script) {
  std::string bash = "bash", path = script.string();
  char* argv[] = {bash.data(), path.data(), nullptr};
  pid_t pid = 0;
  if (posix_spawnp(&pid, "bash", nullptr, nullptr, argv, environ) != 0) return -1;
  int status = 0;
  if (waitpid(pid, &status, 0) != pid) return -1;
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

void AddPlan(CLI::App* tiles, int& exit_code) {
  struct Args {
    TilePlanOptions plan;
    std::string method = "fast";
    bool quantised = false;
    bool no_photo_cache = false;
  };
  auto args = std::make_shared<Args>();
  CLI::App* c = tiles->add_subcommand(
      "plan",
      "Cut a painting's fit into tiles: writes the plan (a JSON job manifest: inputs, every fit "
      "option, the tiles) that `tiles run`, `tiles merge` and `tiles sbatch` take.");
  c->add_option("--canvas", args->plan.canvas, "Folder written by `digitize preprocess`")
      ->required()
      ->check(CLI::ExistingDirectory);
  c->add_option("--photos", args->plan.photos, "Calibration JSON of the photos")
      ->required()
      ->check(CLI::ExistingFile);
  c->add_option("-o,--out", args->plan.out,
                "The pack `tiles merge` writes (e.g. painting.pack.exr)")
      ->required();
  c->add_option("--plan", args->plan.plan, "The plan file to write (e.g. painting.plan.json)")
      ->required();
  c->add_option("--work", args->plan.work,
                "Folder of the tile results (default: beside the plan, PLAN.tiles/)")
      ->transform(FolderPath());
  c->add_option("--tile-size", args->plan.tile_size, "Tile side, texels")
      ->capture_default_str()
      ->check(CLI::Range(kMinTileSize, kMaxTileSize));
  c->add_option("--method", args->method,
                "fast (variable projection) or ceres (ceres::Solve reference)")
      ->check(CLI::IsMember({"fast", "ceres"}))
      ->capture_default_str()
      ->group("Fit");
  c->add_flag("--no-photo-cache", args->no_photo_cache,
              "Do not copy PNG / JPEG photos into tiled TIFFs in the work folder (the jobs then "
              "decode every row above the part of a photo they read; the copies take ~5x the "
              "JPEGs' disk space)");
  AddFitFlags(c, args->plan.fit, args->plan.photo);
  AddPhotoSetFlags(c, args->plan.photo);
  AddPackWriteFlags(c, args->plan.pack, args->quantised);
  c->callback([args, &exit_code] {
    TilePlanOptions o = args->plan;
    SetFitMethod(o.fit, args->method, 0);
    o.pack.encoding = args->quantised ? PackEncoding::kQuantised : PackEncoding::kHalf;
    auto plan = MakeTilePlan(o);
    if (!plan.ok()) {
      exit_code = Fail("tiles plan", plan.error().message);
      return;
    }
    std::printf("%s: %d x %d texels in %zu tiles of %d; work folder %s\n",
                EscapeForTerminal(plan->file.string()).c_str(), plan->canvas_width,
                plan->canvas_height, plan->tiles.size(), plan->tile_size,
                EscapeForTerminal(plan->work.string()).c_str());
    // The window a job reads is its tile and this halo all round: with a tile side under 4 halos
    // a job spends more on its window (reading, tracer, horizons) than on its tile.
    if (auto halo = LargestTileHalo(*plan); halo.ok()) {
      const int t = plan->tile_size, h = *halo;
      const double window = (t + 2.0 * h) * (t + 2.0 * h) / (static_cast<double>(t) * t);
      std::printf(
          "halo: up to %d texels around a tile (shadows and hidden strips of the relief): "
          "a job reads up to %.1fx its tile\n",
          h, window);
      if (t < 4 * h && 4 * h <= kMaxTileSize) {
        // The next multiple of 256 (whole pack tiles): larger tiles cost memory per job.
        const int suggest = (4 * h + 255) / 256 * 256;
        std::printf(
            "hint: --tile-size %d (at least 4 halos) keeps a job's window under 2.3x its "
            "tile; the fit's time per texel then stays flat (docs/cluster.md)\n",
            std::min(suggest, kMaxTileSize));
      }
    }
    if (!args->no_photo_cache) {
      // Once here, not in the jobs: array tasks would race to make the same copies.
      ProgressBar bar("photo tile cache");
      auto cache = CachePlanPhotos(*plan, bar.Callback());
      bar.Finish();
      // The copies only save time: without them the jobs read the photos themselves.
      if (!cache.ok())
        Warn("tiles plan", "photo cache not made (" + EscapeForTerminal(cache.error().message) +
                               "); the tile jobs will read the photos themselves");
      else
        std::printf("photo cache: %s -> %s\n", cache->Brief().c_str(),
                    EscapeForTerminal(plan->PhotoCacheFolder().string()).c_str());
    }
    std::printf("next: digitize tiles run %s --all   (or: digitize tiles sbatch %s)\n",
                EscapeForTerminal(plan->file.string()).c_str(),
                EscapeForTerminal(plan->file.string()).c_str());
    exit_code = 0;
  });
}

void AddRun(CLI::App* tiles, int& exit_code) {
  struct Args {
    std::string plan;
    std::vector<size_t> indices;
    bool all = false;
    TileRunOptions run;
  };
  auto args = std::make_shared<Args>();
  CLI::App* c = tiles->add_subcommand(
      "run",
      "Fit tiles of a plan: --index I (one Slurm array task), or --all (every tile not done yet, "
      "with every core). Tiles already done are skipped, so a killed run resumes where it "
      "stopped.");
  c->add_option("plan", args->plan, "Plan file (`digitize tiles plan`)")->required();
  CLI::Option* index = c->add_option("--index", args->indices, "Tile index (repeatable)");
  CLI::Option* all = c->add_flag("--all", args->all, "Every tile not done yet");
  index->excludes(all);
  c->add_flag("--redo", args->run.redo, "Fit tiles that are done again");
  c->add_option("--cache-mb", args->run.cache_mb,
                "Memory bound of the image cache the canvas windows and photo parts are read "
                "through (MB, >= 64)")
      ->capture_default_str();
  c->add_option("--threads", args->run.threads, "Worker threads (0 = all cores)")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  c->callback([args, &exit_code] {
    if (!args->all && args->indices.empty()) {
      exit_code = Fail("tiles run", "say which tiles: --index I or --all");
      return;
    }
    auto plan = ReadTilePlan(args->plan);
    if (!plan.ok()) {
      exit_code = Fail("tiles run", plan.error().message);
      return;
    }
    TileRunOptions o = args->run;
    o.indices = args->indices;
    ProgressBar bar("tiles run");
    auto report = RunTiles(*plan, o, bar.Callback());
    bar.Finish();
    if (!report.ok()) {
      exit_code = Fail("tiles run", report.error().message);
      return;
    }
    std::printf("%s\n", report->Brief().c_str());
    auto status = StatusOfTiles(*plan);
    if (status.ok()) std::printf("%s\n", status->Brief().c_str());
    exit_code = 0;
  });
}

void AddStatus(CLI::App* tiles, int& exit_code) {
  auto plan_file = std::make_shared<std::string>();
  CLI::App* c = tiles->add_subcommand(
      "status", "Which tiles of a plan are done. Exit 0 when every tile is done, 2 otherwise.");
  c->add_option("plan", *plan_file, "Plan file")->required();
  c->callback([plan_file, &exit_code] {
    auto plan = ReadTilePlan(*plan_file);
    if (!plan.ok()) {
      exit_code = Fail("tiles status", plan.error().message);
      return;
    }
    auto status = StatusOfTiles(*plan);
    if (!status.ok()) {
      exit_code = Fail("tiles status", status.error().message);
      return;
    }
    std::printf("%s\n", status->Brief().c_str());
    exit_code = status->pending.empty() ? 0 : 2;
  });
}

void AddMerge(CLI::App* tiles, int& exit_code) {
  auto plan_file = std::make_shared<std::string>();
  CLI::App* c = tiles->add_subcommand(
      "merge",
      "Every tile done -> the merged fit folder (WORK/fit) and the plan's pack (written "
      "atomically, never over an input).");
  c->add_option("plan", *plan_file, "Plan file")->required();
  c->callback([plan_file, &exit_code] {
    auto plan = ReadTilePlan(*plan_file);
    if (!plan.ok()) {
      exit_code = Fail("tiles merge", plan.error().message);
      return;
    }
    ProgressBar bar("tiles merge");
    auto merged = MergeTiles(*plan, bar.Callback());
    bar.Finish();
    if (!merged.ok()) {
      exit_code = Fail("tiles merge", merged.error().message);
      return;
    }
    for (const std::string& w : merged->fit.Warnings()) Warn("tiles merge", w);
    std::printf("%s\n", merged->fit.Brief().c_str());
    std::printf("fit folder: %s\n", EscapeForTerminal(plan->FitFolder().string()).c_str());
    PrintPackSummaryLine(plan->out.string(), merged->pack);
    exit_code = 0;
  });
}

void AddSbatch(CLI::App* tiles, int& exit_code) {
  struct Args {
    std::string plan;
    SlurmScriptOptions slurm;
    bool submit = false;
  };
  auto args = std::make_shared<Args>();
  CLI::App* c = tiles->add_subcommand(
      "sbatch",
      "Write Slurm scripts for a plan: a job array of the tiles and the merge as a job that "
      "depends on it (WORK/slurm/), and with --submit submit them (docs/cluster.md).");
  c->add_option("plan", args->plan, "Plan file")->required();
  c->add_option("--cpus-per-task", args->slurm.cpus_per_task, "Cores of each tile job")
      ->capture_default_str();
  c->add_option("--mem-mb", args->slurm.mem_mb, "Memory of each job, MB (0: the cluster's default)")
      ->capture_default_str();
  c->add_option("--partition", args->slurm.partition, "Slurm partition (default: the cluster's)");
  c->add_option("--time", args->slurm.time, "Time limit of each job (e.g. 2:00:00)");
  c->add_option("--max-running", args->slurm.max_running,
                "At most this many tiles at once (0: no limit)")
      ->capture_default_str();
  c->add_flag("--submit", args->submit, "Run submit.sh: sbatch the array, then the merge");
  c->callback([args, &exit_code] {
    auto plan = ReadTilePlan(args->plan);
    if (!plan.ok()) {
      exit_code = Fail("tiles sbatch", plan.error().message);
      return;
    }
    SlurmScriptOptions o = args->slurm;
    o.digitize = SelfPath();
    auto scripts = WriteSlurmScripts(*plan, o);
    if (!scripts.ok()) {
      exit_code = Fail("tiles sbatch", scripts.error().message);
      return;
    }
    std::printf("wrote %s, %s, %s\n", EscapeForTerminal(scripts->tiles.string()).c_str(),
                EscapeForTerminal(scripts->merge.string()).c_str(),
                EscapeForTerminal(scripts->submit.string()).c_str());
    if (!args->submit) {
      std::printf("submit with: bash %s\n", EscapeForTerminal(scripts->submit.string()).c_str());
      exit_code = 0;
      return;
    }
    std::fflush(stdout);
    exit_code = RunBash(scripts->submit) == 0
                    ? 0
                    : Fail("tiles sbatch", scripts->submit.string() +
                                               " failed (is sbatch installed, is the cluster up?)");
  });
}

}  // namespace

void AddTilesCommand(CLI::App& app, int& exit_code) {
  CLI::App* tiles = app.add_subcommand(
      "tiles",
      "A painting larger than one fit: cut into tiles (plan), fitted one by one, on every core "
      "(run --all) or as Slurm jobs (sbatch), then merged into one pack (merge). "
      "docs/cluster.md.");
  tiles->require_subcommand(1);
  AddPlan(tiles, exit_code);
  AddRun(tiles, exit_code);
  AddStatus(tiles, exit_code);
  AddMerge(tiles, exit_code);
  AddSbatch(tiles, exit_code);
}

}  // namespace digitize::cli
