#pragma once

// UniqueFd: owns one file descriptor and closes it on destruction (the only
// place in the product that calls close(2) on a descriptor it owns).

namespace scaled::drivers::base {

// Owns one file descriptor and closes it on destruction. Move-only.
class UniqueFd {
public:
    UniqueFd() = default;
    explicit UniqueFd(int fd) : fd_(fd) {}
    ~UniqueFd() { reset(); }
    UniqueFd(const UniqueFd&) = delete;
    UniqueFd& operator=(const UniqueFd&) = delete;
    UniqueFd(UniqueFd&& other) noexcept : fd_(other.release()) {}
    UniqueFd& operator=(UniqueFd&& other) noexcept {
        if (this != &other) {
            reset(other.release());
        }
        return *this;
    }

    [[nodiscard]] int get() const { return fd_; }
    [[nodiscard]] bool isValid() const { return fd_ >= 0; }
    // Gives up ownership; the caller closes the returned descriptor.
    [[nodiscard]] int release() {
        const int fd = fd_;
        fd_ = -1;
        return fd;
    }
    // Closes the owned descriptor (if any) and owns `fd` instead.
    void reset(int fd = -1);
    // Closes the owned descriptor now and reports how that went: 0, or the
    // errno of close(2) (a file whose last write-back failed says so here).
    // The descriptor is released either way.
    [[nodiscard]] int close();

private:
    int fd_ = -1;
};

}  // namespace scaled::drivers::base
