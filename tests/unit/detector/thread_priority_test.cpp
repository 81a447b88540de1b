// The detector's priority (thread_priority.h): OpenCV's workers take the nice
// value of the thread that made the process's first parallel call. A test
// binary of its own: the worker pool is process-wide and made once.

#include <dirent.h>
#include <fstream>
#include <opencv2/core/utility.hpp>
#include <set>
#include <sstream>
#include <string>
#include <sys/syscall.h>
#include <thread>
#include <unistd.h>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/drivers/detector/thread_priority.h>

namespace {

struct TaskInfo {
    long tid = 0;
    std::string name;
    int nice = 0;
};

// Every thread of this process from /proc/self/task/TID/stat (field 19: nice).
std::vector<TaskInfo> tasks() {
    std::vector<TaskInfo> out;
    DIR* dir = ::opendir("/proc/self/task");
    if (dir == nullptr) {
        return out;
    }
    while (const dirent* e = ::readdir(dir)) {
        if (e->d_name[0] == '.') {
            continue;
        }
        std::ifstream in(std::string("/proc/self/task/") + e->d_name + "/stat");
        std::string line;
        std::getline(in, line);
        const auto open = line.find('(');
        const auto close = line.rfind(')');
        if (open == std::string::npos || close == std::string::npos) {
            continue;
        }
        TaskInfo t;
        t.tid = std::stol(e->d_name);
        t.name = line.substr(open + 1, close - open - 1);
        std::istringstream rest(line.substr(close + 2));
        std::string field;
        // After the name: state (3), ppid, pgrp, session, tty_nr, tpgid, flags,
        // minflt, cminflt, majflt, cmajflt, utime, stime, cutime, cstime,
        // priority (18), nice (19).
        for (int i = 3; i <= 19 && rest >> field; ++i) {
            if (i == 19) {
                t.nice = std::stoi(field);
            }
        }
        out.push_back(t);
    }
    ::closedir(dir);
    return out;
}

TEST(ThreadPriority, OpenCvWorkersInheritTheNiceValueOfTheirStarter) {
    const long main_tid = ::syscall(SYS_gettid);
    std::set<long> before;
    for (const auto& t : tasks()) {
        before.insert(t.tid);
    }
    auto threads = scaled::drivers::detector::startOpenCvWorkersAtNice(7);
    ASSERT_TRUE(threads) << threads.error().message;
    if (*threads < 2) {
        GTEST_SKIP() << "OpenCV runs on " << *threads << " thread: no workers to check";
    }
    // A parallel call from this (nice 0) thread reuses the workers made above.
    cv::parallel_for_(cv::Range(0, 256), [](const cv::Range&) {});
    int workers = 0;
    for (const auto& t : tasks()) {
        if (t.tid == main_tid) {
            EXPECT_EQ(t.nice, 0) << "the calling thread keeps its priority";
            continue;
        }
        if (before.count(t.tid) > 0) {
            continue;  // gtest's or the loader's own threads, if any
        }
        ++workers;
        EXPECT_EQ(t.nice, 7) << "thread " << t.tid << " (" << t.name << ")";
        EXPECT_EQ(t.name, "scaled-dnn") << "thread " << t.tid;
    }
    EXPECT_GE(workers, 1) << "OpenCV reports " << *threads << " threads but made no worker";
    EXPECT_EQ(scaled::drivers::detector::threadNice(), 0);
}

TEST(ThreadPriority, NiceOutsideItsRangeIsRefusedAndNamed) {
    for (const int bad : {-1, 20}) {
        auto r = scaled::drivers::detector::setThreadNice(bad);
        ASSERT_FALSE(r);
        EXPECT_NE(r.error().message.find("detector.nice: must be an integer in [0, 19] (got " +
                                         std::to_string(bad) + ")"),
                  std::string::npos)
            << r.error().message;
    }
}

TEST(ThreadPriority, AThreadCanLowerItsOwnPriority) {
    int seen = -1;
    std::thread t([&] {
        ASSERT_TRUE(scaled::drivers::detector::setThreadNice(12));
        seen = scaled::drivers::detector::threadNice();
    });
    t.join();
    EXPECT_EQ(seen, 12);
    EXPECT_EQ(scaled::drivers::detector::threadNice(), 0) << "only the thread that asked";
}

}  // namespace
