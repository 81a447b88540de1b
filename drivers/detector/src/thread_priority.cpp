#include <algorithm>
#include <atomic>
#include <cerrno>
#include <opencv2/core/utility.hpp>
#include <pthread.h>
#include <string>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <system_error>
#include <thread>
#include <unistd.h>

#include <scaled/drivers/detector/thread_priority.h>

namespace scaled::drivers::detector {
namespace {

id_t threadId() {
    return static_cast<id_t>(::syscall(SYS_gettid));
}

}  // namespace

core::Status setThreadNice(int nice) {
    if (nice < kMinNice || nice > kMaxNice) {
        return core::makeError(core::ErrorCode::kInvalidArgument,
                               "detector.nice: must be an integer in [" + std::to_string(kMinNice) +
                                   ", " + std::to_string(kMaxNice) + "] (got " +
                                   std::to_string(nice) + ")");
    }
    if (::setpriority(PRIO_PROCESS, threadId(), nice) != 0) {
        const int err = errno;
        return core::makeError(core::ErrorCode::kIo,
                               "cannot set the thread's nice value to " + std::to_string(nice) +
                                   ": " + std::error_code(err, std::generic_category()).message());
    }
    return {};
}

int threadNice() {
    errno = 0;
    const int nice = ::getpriority(PRIO_PROCESS, threadId());
    return errno == 0 ? nice : 0;
}

core::Result<int> startOpenCvWorkersAtNice(int nice) {
    core::Status set;
    try {
        std::thread starter([&] {
            ::pthread_setname_np(::pthread_self(), "scaled-dnn");
            set = setThreadNice(nice);
            if (!set) {
                return;
            }
            // Enough independent pieces that every worker is woken (and so
            // created); each piece is a few arithmetic operations.
            const int pieces = 64 * std::max(cv::getNumThreads(), 1);
            std::atomic<int> done{0};
            cv::parallel_for_(cv::Range(0, pieces), [&](const cv::Range& r) {
                done.fetch_add(r.end - r.start, std::memory_order_relaxed);
            });
        });
        starter.join();
    } catch (const std::system_error& e) {
        return core::makeError(core::ErrorCode::kIo,
                               std::string("cannot start a thread: ") + e.what());
    } catch (const cv::Exception& e) {
        return core::makeError(core::ErrorCode::kIo, std::string("OpenCV: ") + e.what());
    }
    if (!set) {
        return set.error();
    }
    return cv::getNumThreads();
}

}  // namespace scaled::drivers::detector
