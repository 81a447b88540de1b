#pragma once

// The detector's CPU priority below the threads that must keep time (the
// tracker, the socket, the capture): on a two-core board the network's
// inference would otherwise take both cores from them (docs/benchmarks.md,
// "Detector priority").
//
// Linux nice values belong to threads, and a new thread starts with the nice
// value of the thread that created it. OpenCV's parallel back end (TBB or its
// own pthreads pool) creates its worker threads once, on the first parallel
// call, and keeps them; so the workers get the detector's priority only when
// a thread at that priority makes the first parallel call in the process:
// startOpenCvWorkersAtNice() does that, and must run before anything else
// calls a parallel OpenCV function.

#include <scaled/core/result.h>

namespace scaled::drivers::detector {

inline constexpr int kMinNice = 0;
inline constexpr int kMaxNice = 19;

// Sets the calling thread's nice value (in [kMinNice, kMaxNice]). Raising a
// priority back needs CAP_SYS_NICE: an unprivileged thread can only lower it.
[[nodiscard]] core::Status setThreadNice(int nice);

// The calling thread's nice value.
[[nodiscard]] int threadNice();

// Runs one parallel OpenCV call from a new thread at `nice` (named
// "scaled-dnn"), so that OpenCV's worker threads are created there and
// inherit that nice value and name. Returns the number of threads OpenCV
// uses (cv::getNumThreads()).
[[nodiscard]] core::Result<int> startOpenCvWorkersAtNice(int nice);

}  // namespace scaled::drivers::detector
