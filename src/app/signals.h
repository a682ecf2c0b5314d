// SIGINT and SIGTERM as a request to stop: the first one sets a flag the renderer checks
// at every tile boundary (the render then saves what it has); a second SIGINT or SIGTERM
// ends the process at once with the signal's exit code (128 + its number: 130, 143).
#pragma once
#include <atomic>

namespace tuile {

// Installs the handlers (idempotent). The flag is set by the first signal.
const std::atomic<bool>& install_stop_signals();
// The signal that set the flag (SIGINT or SIGTERM), 0 if none.
int stop_signal();
// The exit code for a render stopped by that signal: 128 + its number.
inline int exit_code_for_signal(int sig) { return 128 + sig; }

}  // namespace tuile
