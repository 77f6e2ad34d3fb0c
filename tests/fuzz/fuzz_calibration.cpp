// libFuzzer target: the calibration JSON parser (ParseCalibrationText: JSON syntax, then every
// field of docs/formats.md, "Calibration JSON"), no filesystem involved. Every input must keep
// the contract of parser_contract.h. Seed corpus: corpus/fuzz_calibration/; dictionary:
// fuzz_calibration.dict.
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "fuzz_check.h"
#include "parser_contract.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  digitize::fuzz::AbortUnless(
      digitize::fuzz::CheckCalibrationText(text, digitize::fuzz::kCalibrationSource));
  return 0;
}
