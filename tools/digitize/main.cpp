// digitize: scanned painting -> relightable digital copy. See README.md and `digitize --help`.
#include <cstdio>
#include <exception>

#include "commands.h"
#include "digitize/core.h"

namespace digitize::cli {

int Fail(const std::string& command, const std::string& message) {
  std::fprintf(stderr, "digitize %s: error: %s\n", command.c_str(), message.c_str());
  return 1;
}

}  // namespace digitize::cli

int main(int argc, char** argv) {
  CLI::App app{
      "digitize: turn a scanned painting into a compact, relightable, real-time digital copy.\n"
      "Start with `digitize demo`, then `digitize <command> --help`."};
  app.require_subcommand(1);
  app.set_version_flag("--version", std::string("digitize ") + DIGITIZE_VERSION);
  int exit_code = 0;
  digitize::cli::AddSynthCommand(app, exit_code);
  digitize::cli::AddPreprocessCommand(app, exit_code);
  digitize::cli::AddFitCommand(app, exit_code);
  digitize::cli::AddPackCommand(app, exit_code);
  digitize::cli::AddRunCommand(app, exit_code);
  digitize::cli::AddInspectCommand(app, exit_code);
  digitize::cli::AddVerifyCommand(app, exit_code);
  digitize::cli::AddDemoCommand(app, exit_code);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const digitize::InvariantError& e) {
    std::fprintf(stderr, "digitize: internal error (please report): %s\n", e.what());
    return 3;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "digitize: error: %s\n", e.what());
    return 1;
  }
  return exit_code;
}
