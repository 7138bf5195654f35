// SPDX-License-Identifier: MIT
#include "progress.hpp"

#include <nbmc.h>

#include <algorithm>
#include <atomic>
#include <csignal>
#include <cstdio>
#include <string>

namespace nbmc::cli {

namespace {

std::atomic<bool> g_interrupted{false};
static_assert(std::atomic<bool>::is_always_lock_free, "the signal handler needs a lock-free flag");

extern "C" void on_sigint(int) {
  if (g_interrupted.load()) { // second Ctrl-C: stop now
    std::signal(SIGINT, SIG_DFL);
    std::raise(SIGINT);
    return;
  }
  g_interrupted.store(true);
}

constexpr auto kRedrawInterval = std::chrono::milliseconds(100);
constexpr int kBarWidth = 30;

} // namespace

void install_interrupt_handler() {
  struct sigaction sa {};
  sa.sa_handler = on_sigint;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = SA_RESTART;
  sigaction(SIGINT, &sa, nullptr);
}

bool interrupted() { return g_interrupted.load(); }

std::int32_t Progress::callback(void* self, std::int32_t stage, double fraction) {
  if (g_interrupted.load()) return 1;
  auto* p = static_cast<Progress*>(self);
  if (p && p->show_) {
    const auto now = std::chrono::steady_clock::now();
    if (!p->drawn_ || now - p->last_ >= kRedrawInterval) {
      p->last_ = now;
      p->draw(stage, fraction);
    }
  }
  return 0;
}

void Progress::draw(std::int32_t stage, double fraction) {
  if (!(fraction >= 0)) fraction = 0; // also NaN
  fraction = std::min(fraction, 1.0);
  const char* name = nbmc_stage_name(stage);
  const int filled = static_cast<int>(fraction * kBarWidth + 0.5);
  std::string bar(static_cast<std::size_t>(filled), '#');
  bar.resize(kBarWidth, ' ');
  std::fprintf(stderr, "\r%-18s [%s] %3d%% (stage %d/%d)%s", name ? name : "?", bar.c_str(),
               static_cast<int>(fraction * 100.0), stage + 1, NBMC_STAGE_COUNT, tty_ ? "\033[K" : "");
  std::fflush(stderr);
  drawn_ = true;
}

void Progress::finish() {
  if (!drawn_) return;
  std::fputs(tty_ ? "\r\033[K" : "\n", stderr);
  std::fflush(stderr);
  drawn_ = false;
}

} // namespace nbmc::cli
