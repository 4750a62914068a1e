#pragma once
// Progress reporting for long stages, always on stderr (stdout stays for data).
//
// Modes: Bar draws a live bar per stage (for terminals) with the time left once a stage has run
// a second, Json writes one JSON object per line per step (for machines; progress events carry
// the stage's seconds so far and, once a step is done, eta_seconds), Quiet writes nothing. Progress also carries the cancellation flag:
// every call to advance() throws Error(Cancelled) once requestCancel() was called (from the
// SIGINT handler), so long loops stop at the next step.

#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

namespace terratiles {

enum class ProgressMode { Quiet, Bar, Json };

// A finished stage, for reports: its wall time and the process's peak resident memory when
// it ended (the peak so far, so a stage's own need is at most its figure).
struct StageRecord {
  std::string name;
  double seconds = 0;
  std::uint64_t peak_rss_bytes = 0;
};

// The process's peak resident set size so far (getrusage), in bytes.
std::uint64_t peakResidentBytes();

class Progress {
 public:
  explicit Progress(ProgressMode mode = ProgressMode::Quiet, std::FILE* stream = stderr);
  ~Progress();
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  // Starts a stage of `total` steps (0 when unknown); ends the previous stage.
  void beginStage(const std::string& name, std::uint64_t total);
  // Adds `steps` done steps to the current stage. Throws Error(Cancelled) when cancelled.
  void advance(std::uint64_t steps = 1);
  void endStage();
  // Free-form line (for example "geoid: EGM96"); shown in Bar mode, a JSON line in Json mode.
  void note(const std::string& message);

  // Async-signal-safe: only sets an atomic flag.
  static void requestCancel();
  static bool cancelRequested();
  static void resetCancel();
  void throwIfCancelled() const;

  // Every stage ended so far, in order (in every mode).
  const std::vector<StageRecord>& stages() const { return stages_; }

 private:
  void draw(bool final_line);
  // Seconds the current stage still needs at its rate so far; -1 when unknown.
  double remainingSeconds(std::chrono::steady_clock::time_point now) const;

  ProgressMode mode_;
  std::FILE* stream_;
  std::string stage_;
  std::uint64_t total_ = 0;
  std::uint64_t done_ = 0;
  int last_permille_ = -1;
  bool in_stage_ = false;
  std::chrono::steady_clock::time_point stage_start_;
  std::chrono::steady_clock::time_point last_draw_;
  std::vector<StageRecord> stages_;
};

}  // namespace terratiles
