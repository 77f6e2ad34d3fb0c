// digitize: scanned painting -> relightable digital copy. See README.md and `digitize --help`.
#include <cstdio>
#include <exception>
#include <string>

#include "commands.h"
#include "digitize/core.h"

int main(int argc, char** argv) {
  CLI::App app{
      "digitize: turn a scanned painting into a compact, relightable, real-time digital copy.\n"
      "Start with `digitize demo`, then `digitize <command> --help`."};
  app.require_subcommand(1);
  app.set_version_flag(
      "--version", std::string("digitize ") + DIGITIZE_VERSION + " (" + DIGITIZE_SIMD_LEVEL + ")");
  int exit_code = 0;
  digitize::cli::AddSynthCommand(app, exit_code);
  digitize::cli::AddPreprocessCommand(app, exit_code);
  digitize::cli::AddFitCommand(app, exit_code);
  digitize::cli::AddPackCommand(app, exit_code);
  digitize::cli::AddRunCommand(app, exit_code);
  digitize::cli::AddRtiCommand(app, exit_code);
  digitize::cli::AddTilesCommand(app, exit_code);
  digitize::cli::AddInspectCommand(app, exit_code);
  digitize::cli::AddVerifyCommand(app, exit_code);
  digitize::cli::AddDemoCommand(app, exit_code);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // A mistyped command or option before it reads to CLI11 as "a subcommand is required": say
    // what was not understood.
    if (app.get_subcommands().empty() && !app.remaining().empty()) {
      const std::string word = app.remaining().front();  // remaining() returns a copy
      std::string commands;
      for (const CLI::App* c : app.get_subcommands({})) commands += " " + c->get_name();
      std::fprintf(stderr, "digitize: error: unknown %s \"%s\" (commands:%s)\n",
                   word.rfind('-', 0) == 0 ? "option" : "command", word.c_str(), commands.c_str());
      return 1;
    }
    // CLI11 prints the message (or the help / version text) and returns its own code: 0 for
    // --help / --version, 105, 106, 109, ... for usage errors. Every user error exits 1.
    return app.exit(e) == 0 ? 0 : 1;
  } catch (const digitize::InvariantError& e) {
    std::fprintf(stderr, "digitize: internal error (please report): %s\n", e.what());
    return 3;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "digitize: error: %s\n", e.what());
    return 1;
  }
  return exit_code;
}
