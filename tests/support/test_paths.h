// The programs and folders the tests run and read: the digitize CLI, the viewer, the source tree.
// Functions of one small object (test_paths.cpp, the only file compiled with the paths), not
// definitions on every test file's command line: ccache hashes the command line, so a path there
// made every test file miss the cache in a clone at another path (CI's), twice (Release, ASan).
#pragma once

namespace digitize::test {

const char* CliPath();     // build/bin/digitize
const char* SourceDir();   // the checkout
const char* ViewerPath();  // build/bin/digitize-viewer, "" where the viewer is not built

}  // namespace digitize::test

#define DIGITIZE_CLI ::digitize::test::CliPath()
#define DIGITIZE_SOURCE_DIR ::digitize::test::SourceDir()
// Test files that run the viewer are skipped where it is not built (#ifdef DIGITIZE_VIEWER).
#ifdef DIGITIZE_HAS_VIEWER
#define DIGITIZE_VIEWER ::digitize::test::ViewerPath()
#endif
