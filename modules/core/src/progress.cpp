#include <paps/core/progress.h>

#include <mutex>

namespace paps {

namespace {
std::mutex& callbackMutex() {
  static std::mutex m;
  return m;
}
}  // namespace

ProgressReporter::ProgressReporter(const ProgressCallback& cb, std::string stage, std::size_t total)
    : cb_(cb ? &cb : nullptr), stage_(std::move(stage)), total_(total),
      step_(total / 100 > 0 ? total / 100 : 1) {
  if (cb_ && !(*cb_)(stage_, 0.f)) cancelled_ = true;
  next_report_ = step_;
}

void ProgressReporter::advance(std::size_t n) {
  if (!cb_) return;
  const std::size_t done = done_.fetch_add(n, std::memory_order_relaxed) + n;
  std::size_t next = next_report_.load(std::memory_order_relaxed);
  if (done < next) return;
  // Only the thread that moves the mark reports.
  if (!next_report_.compare_exchange_strong(next, done + step_)) return;
  std::lock_guard<std::mutex> lock(callbackMutex());
  const float f = total_ ? static_cast<float>(done) / static_cast<float>(total_) : 1.f;
  if (!(*cb_)(stage_, f > 1.f ? 1.f : f)) cancelled_ = true;
}

void ProgressReporter::finish() {
  if (!cb_) return;
  std::lock_guard<std::mutex> lock(callbackMutex());
  if (!(*cb_)(stage_, 1.f)) cancelled_ = true;
}

ProgressCallback partProgress(const ProgressCallback& progress, const std::string& part, std::size_t index,
                              std::size_t count) {
  if (!progress) return {};
  const std::string prefix = part + " " + std::to_string(index + 1) + "/" + std::to_string(count) + ": ";
  return [progress, prefix](const std::string& name, float f) { return progress(prefix + name, f); };
}

}  // namespace paps
