#include <cerrno>
#include <unistd.h>

#include <scaled/drivers/base/unique_fd.h>

namespace scaled::drivers::base {

void UniqueFd::reset(int fd) {
    if (fd_ >= 0 && fd_ != fd) {
        ::close(fd_);
    }
    fd_ = fd;
}

int UniqueFd::close() {
    const int fd = release();
    if (fd < 0) {
        return 0;
    }
    // Linux releases the descriptor even when close() fails (EINTR included):
    // never retry.
    return ::close(fd) == 0 ? 0 : errno;
}

}  // namespace scaled::drivers::base
