// The paths test_paths.h gives, from tests/CMakeLists.txt.
#include "test_paths.h"

#ifndef DIGITIZE_VIEWER_PATH
#define DIGITIZE_VIEWER_PATH ""
#endif

namespace digitize::test {

const char* CliPath() { return DIGITIZE_CLI_PATH; }
const char* SourceDir() { return DIGITIZE_SOURCE_DIR_PATH; }
const char* ViewerPath() { return DIGITIZE_VIEWER_PATH; }

}  // namespace digitize::test
