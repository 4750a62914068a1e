#pragma once
// terratiles::Error: the one exception type. Thrown for conditions a user can cause or fix
// (bad options, bad input, unwritable output, interruption); caught once, in runCli, which
// turns the code into the process exit code. Programmer errors use TERRATILES_ASSERT.

#include <stdexcept>
#include <string>

namespace terratiles {

enum class ErrorCode {
  Usage,      // bad command line; exit 2
  Input,      // unreadable or unsupported input; exit 3
  Output,     // output cannot be written; exit 4
  Internal,   // a bug or a library failure we did not expect; exit 1
  OutOfMemory,  // an allocation failed (the machine's memory or a ulimit); exit 6
  Cancelled,  // interrupted (SIGINT); exit 130
};

// Exit code documented in --help and README for each error code.
int exitCodeFor(ErrorCode code);

class Error : public std::runtime_error {
 public:
  // message: one line saying what, where, found versus expected and the fix.
  Error(ErrorCode code, const std::string& message) : std::runtime_error(message), code_(code) {}
  ErrorCode code() const { return code_; }

 private:
  ErrorCode code_;
};

[[noreturn]] void assertionFailed(const char* expression, const char* file, int line);

}  // namespace terratiles

#define TERRATILES_ASSERT(expression) \
  ((expression) ? void(0) : ::terratiles::assertionFailed(#expression, __FILE__, __LINE__))
