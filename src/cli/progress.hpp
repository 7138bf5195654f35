// SPDX-License-Identifier: MIT
// Progress bar on stderr and Ctrl-C cancellation for the nbmc command.
#ifndef NBMC_CLI_PROGRESS_HPP
#define NBMC_CLI_PROGRESS_HPP

#include <chrono>
#include <cstdint>

namespace nbmc::cli {

// Installs a SIGINT handler that sets the cancellation flag; a second Ctrl-C
// ends the process the usual way.
void install_interrupt_handler();
bool interrupted();

// Draws "stage [#####     ]  45%" on stderr, at most ~10 times a second.
// Its callback (an nbmc_progress_fn) also turns Ctrl-C into cancellation,
// whether or not the bar is shown.
class Progress {
public:
  Progress(bool show, bool tty) : show_(show), tty_(tty) {}
  static std::int32_t callback(void* self, std::int32_t stage, double fraction);
  // Removes the bar (call before printing anything else).
  void finish();

private:
  void draw(std::int32_t stage, double fraction);

  bool show_;
  bool tty_;
  bool drawn_ = false;
  std::chrono::steady_clock::time_point last_{};
};

} // namespace nbmc::cli

#endif
