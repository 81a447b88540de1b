#pragma once

// Result<T>: a value or an Error; Status (Result<void>): ok or an Error.
// Module boundaries return these instead of throwing. Both are [[nodiscard]]:
// an error nobody looked at is a bug. (std::expected is C++23; this is the
// small subset we need.)

#include <optional>
#include <string>
#include <utility>
#include <variant>

namespace scaled::core {

enum class ErrorCode {
    kInvalidArgument,  // a parameter out of its allowed range
    kParse,            // malformed input text
    kIo,               // a file could not be read or written
    kNotFound,         // a named thing does not exist
    kDegenerate,       // geometry gives no usable answer (not a bug, just no data)
    kUnavailable,      // a device or service is gone, busy or silent; trying again later may work
};

struct Error {
    ErrorCode code;
    std::string message;
};

template <typename T>
class [[nodiscard]] Result {
public:
    Result(T value) : v_(std::move(value)) {}      // NOLINT(google-explicit-constructor)
    Result(Error error) : v_(std::move(error)) {}  // NOLINT(google-explicit-constructor)

    [[nodiscard]] bool ok() const { return v_.index() == 0; }
    explicit operator bool() const { return ok(); }

    T& value() & { return std::get<0>(v_); }
    const T& value() const& { return std::get<0>(v_); }
    T&& value() && { return std::get<0>(std::move(v_)); }
    T& operator*() & { return value(); }
    const T& operator*() const& { return value(); }
    T* operator->() { return &value(); }
    const T* operator->() const { return &value(); }

    [[nodiscard]] const Error& error() const { return std::get<1>(v_); }

private:
    std::variant<T, Error> v_;
};

// Ok or an Error, for operations that give nothing back but can fail.
template <>
class [[nodiscard]] Result<void> {
public:
    Result() = default;                                // ok
    Result(Error error) : error_(std::move(error)) {}  // NOLINT(google-explicit-constructor)

    [[nodiscard]] bool ok() const { return !error_.has_value(); }
    explicit operator bool() const { return ok(); }
    [[nodiscard]] const Error& error() const { return *error_; }

private:
    std::optional<Error> error_;
};

using Status = Result<void>;

inline Error makeError(ErrorCode code, std::string message) {
    return Error{code, std::move(message)};
}

}  // namespace scaled::core
