#include "src/base/error.h"

#include <cstdio>
#include <cstdlib>

namespace terratiles {

int exitCodeFor(ErrorCode code) {
  switch (code) {
    case ErrorCode::Usage: return 2;
    case ErrorCode::Input: return 3;
    case ErrorCode::Output: return 4;
    case ErrorCode::Internal: return 1;
    case ErrorCode::OutOfMemory: return 6;
    case ErrorCode::Cancelled: return 130;
  }
  return 1;
}

void assertionFailed(const char* expression, const char* file, int line) {
  std::fprintf(stderr, "terratiles: internal error: assertion '%s' failed at %s:%d\n", expression,
               file, line);
  std::abort();
}

}  // namespace terratiles
