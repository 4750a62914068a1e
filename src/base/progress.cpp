#include "src/base/progress.h"

#include <sys/resource.h>

#include <algorithm>
#include <csignal>

#include "src/base/error.h"

namespace terratiles {
namespace {

volatile std::sig_atomic_t g_cancel_requested = 0;

std::string jsonEscape(const std::string& text) {
  std::string out;
  for (char c : text) {
    if (c == '"' || c == '\\') {
      out += '\\';
      out += c;
    } else if (static_cast<unsigned char>(c) < 0x20) {
      char buffer[8];
      std::snprintf(buffer, sizeof buffer, "\\u%04x", c);
      out += buffer;
    } else {
      out += c;
    }
  }
  return out;
}

}  // namespace

std::uint64_t peakResidentBytes() {
  rusage usage{};
  if (getrusage(RUSAGE_SELF, &usage) != 0) return 0;
  return static_cast<std::uint64_t>(usage.ru_maxrss) * 1024;  // Linux: kilobytes
}

Progress::Progress(ProgressMode mode, std::FILE* stream) : mode_(mode), stream_(stream) {}

Progress::~Progress() {
  if (in_stage_) endStage();
}

void Progress::requestCancel() { g_cancel_requested = 1; }
bool Progress::cancelRequested() { return g_cancel_requested != 0; }
void Progress::resetCancel() { g_cancel_requested = 0; }

void Progress::throwIfCancelled() const {
  if (cancelRequested()) throw Error(ErrorCode::Cancelled, "interrupted; no output was written");
}

void Progress::beginStage(const std::string& name, std::uint64_t total) {
  if (in_stage_) endStage();
  throwIfCancelled();
  stage_ = name;
  total_ = total;
  done_ = 0;
  last_permille_ = -1;
  in_stage_ = true;
  stage_start_ = std::chrono::steady_clock::now();
  last_draw_ = {};
  if (mode_ == ProgressMode::Json) {
    std::fprintf(stream_, "{\"event\":\"stage\",\"stage\":\"%s\",\"total\":%llu}\n",
                 jsonEscape(stage_).c_str(), static_cast<unsigned long long>(total_));
    std::fflush(stream_);
  } else {
    draw(false);
  }
}

void Progress::advance(std::uint64_t steps) {
  throwIfCancelled();
  done_ += steps;
  if (mode_ == ProgressMode::Quiet) return;
  const int permille = total_ > 0 ? static_cast<int>(1000 * std::min(done_, total_) / total_) : 0;
  const auto now = std::chrono::steady_clock::now();
  // Redraw at most every 100 ms or per 1 % so progress never dominates the work.
  if (permille / 10 == last_permille_ / 10 && now - last_draw_ < std::chrono::milliseconds(100))
    return;
  last_permille_ = permille;
  last_draw_ = now;
  if (mode_ == ProgressMode::Json) {
    const double seconds = std::chrono::duration<double>(now - stage_start_).count();
    const double eta = remainingSeconds(now);
    char eta_text[48] = "";
    if (eta >= 0) std::snprintf(eta_text, sizeof eta_text, ",\"eta_seconds\":%.1f", eta);
    std::fprintf(stream_, "{\"event\":\"progress\",\"stage\":\"%s\",\"done\":%llu,\"total\":%llu,\"seconds\":%.3f%s}\n",
                 jsonEscape(stage_).c_str(), static_cast<unsigned long long>(done_),
                 static_cast<unsigned long long>(total_), seconds, eta_text);
    std::fflush(stream_);
  } else {
    draw(false);
  }
}

void Progress::endStage() {
  if (!in_stage_) return;
  in_stage_ = false;
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - stage_start_).count();
  stages_.push_back({stage_, seconds, peakResidentBytes()});
  if (mode_ == ProgressMode::Json) {
    std::fprintf(stream_,
                 "{\"event\":\"stage_done\",\"stage\":\"%s\",\"seconds\":%.3f,\"peak_rss_bytes\":%llu}\n",
                 jsonEscape(stage_).c_str(), seconds, static_cast<unsigned long long>(stages_.back().peak_rss_bytes));
    std::fflush(stream_);
  } else if (mode_ == ProgressMode::Bar) {
    done_ = total_;
    draw(true);
    std::fprintf(stream_, " %.2f s\n", seconds);
    std::fflush(stream_);
  }
}

void Progress::note(const std::string& message) {
  if (mode_ == ProgressMode::Json) {
    std::fprintf(stream_, "{\"event\":\"note\",\"message\":\"%s\"}\n", jsonEscape(message).c_str());
  } else if (mode_ == ProgressMode::Bar) {
    std::fprintf(stream_, "%s%s\n", in_stage_ ? "\r\033[K" : "", message.c_str());
    if (in_stage_) draw(false);
  }
  std::fflush(stream_);
}

double Progress::remainingSeconds(std::chrono::steady_clock::time_point now) const {
  if (total_ == 0 || done_ == 0 || done_ >= total_) return -1;
  const double seconds = std::chrono::duration<double>(now - stage_start_).count();
  return seconds * static_cast<double>(total_ - done_) / static_cast<double>(done_);
}

void Progress::draw(bool final_line) {
  if (mode_ != ProgressMode::Bar) return;
  constexpr int kWidth = 30;
  const double fraction =
      total_ > 0 ? static_cast<double>(std::min(done_, total_)) / static_cast<double>(total_)
                 : (final_line ? 1.0 : 0.0);
  const int filled = static_cast<int>(fraction * kWidth);
  std::string bar(static_cast<size_t>(filled), '#');
  bar.resize(kWidth, '.');
  // The time left, once the stage has run a second (earlier rates say little).
  char eta_text[40] = "";
  const auto now = std::chrono::steady_clock::now();
  const double eta = final_line ? -1 : remainingSeconds(now);
  if (eta >= 0 && now - stage_start_ >= std::chrono::seconds(1)) {
    const auto whole = static_cast<long long>(eta + 0.5);
    if (whole >= 3600) {
      std::snprintf(eta_text, sizeof eta_text, "  %lldh%02lldm left", whole / 3600, whole / 60 % 60);
    } else {
      std::snprintf(eta_text, sizeof eta_text, "  %lldm%02llds left", whole / 60, whole % 60);
    }
  }
  std::fprintf(stream_, "\r\033[K%-22s [%s] %3d%%%s", stage_.c_str(), bar.c_str(),
               static_cast<int>(fraction * 100), eta_text);
  std::fflush(stream_);
}

}  // namespace terratiles
