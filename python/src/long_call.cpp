// LongCall (bindings.hpp): a long C++ call on a worker thread, the calling thread delivering
// progress and running Python's signal handlers meanwhile, and cancelling the work on Ctrl-C.
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <exception>
#include <mutex>
#include <thread>

#include "bindings.hpp"

namespace tsah::python {

// How often the calling thread looks for signals while the work runs: Ctrl-C is seen within this
// time, and the work's cancel check within its own polling interval after that.
constexpr std::chrono::milliseconds kSignalPollInterval{50};

struct LongCall::State {
  std::mutex mutex;
  std::condition_variable wake;
  std::deque<std::function<py::object()>> events;
  bool done = false;
  std::atomic<bool> cancel{false};
  py::object progress;
};

LongCall::LongCall(py::object progress) : state_(std::make_unique<State>()) {
  if (!progress.is_none() && !PyCallable_Check(progress.ptr()))
    throw ArgumentTypeError("progress: expected a callable or None, got " +
                            std::string(py::str(progress.get_type().attr("__name__"))));
  state_->progress = std::move(progress);
}

// The callback is a Python object: released with the GIL held (the destructor runs in the binding).
LongCall::~LongCall() = default;

// The flag, not the state: copies of the check made on worker threads must not own the state and
// its Python callback (released without the GIL). The LongCall outlives run(), and so the work.
std::function<bool()> LongCall::cancelled() const {
  return [flag = &state_->cancel] { return flag->load(std::memory_order_relaxed); };
}

bool LongCall::reports() const { return !state_->progress.is_none(); }

void LongCall::report(std::function<py::object()> event) {
  if (!reports()) return;
  {
    const std::lock_guard lock(state_->mutex);
    state_->events.push_back(std::move(event));
  }
  state_->wake.notify_all();
}

void LongCall::runErased(const std::function<void()>& work) {
  State& s = *state_;
  s.done = false;
  s.cancel = false;
  std::exception_ptr workError, callbackError;
  std::optional<py::error_already_set> pythonError;
  std::thread worker([&] {
    try {
      work();
    } catch (...) {
      workError = std::current_exception();
    }
    {
      const std::lock_guard lock(s.mutex);
      s.done = true;
    }
    s.wake.notify_all();
  });
  // Nothing below may throw before the join: the worker uses this frame.
  for (bool done = false; !done;) {
    std::deque<std::function<py::object()>> events;
    {
      py::gil_scoped_release release;
      std::unique_lock lock(s.mutex);
      s.wake.wait_for(lock, kSignalPollInterval, [&s] { return s.done || !s.events.empty(); });
      events.swap(s.events);
      done = s.done;
    }
    if (pythonError || callbackError) continue;  // cancelled: only waiting for the work to stop
    try {
      for (const auto& event : events) s.progress(event());
      if (PyErr_CheckSignals() != 0) throw py::error_already_set();
    } catch (py::error_already_set& e) {
      pythonError.emplace(std::move(e));
      s.cancel = true;
    } catch (...) {
      callbackError = std::current_exception();
      s.cancel = true;
    }
  }
  worker.join();
  if (pythonError) {
    pythonError->restore();
    throw py::error_already_set();
  }
  if (callbackError) std::rethrow_exception(callbackError);
  if (workError) std::rethrow_exception(workError);
}

}  // namespace tsah::python
