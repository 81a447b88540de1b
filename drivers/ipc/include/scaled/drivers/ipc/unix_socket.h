#pragma once

// The operating-system side of a UNIX stream server: an owning file
// descriptor, the listening socket (created at a path, or inherited from
// systemd socket activation) and a non-blocking accept.
//
// Every descriptor made here is close-on-exec and non-blocking. Errors name
// the path and the errno text, e.g.
// `/run/scaled/scaled.sock: cannot bind: Permission denied`.

#include <filesystem>
#include <optional>
#include <string>
#include <sys/types.h>

#include <scaled/core/result.h>
#include <scaled/drivers/base/unique_fd.h>

namespace scaled::drivers::ipc {

// How to create a listening socket at a path.
struct UnixListenOptions {
    std::filesystem::path path;
    unsigned mode = 0660;  // applied with chmod after bind: independent of the umask
    std::string group;     // owning group (chown); empty: leave the process's group
    int backlog = 64;
};

struct ListeningSocket {
    base::UniqueFd fd;           // listening, non-blocking, close-on-exec
    std::filesystem::path path;  // the socket's file
    bool activated = false;      // inherited from the service manager (LISTEN_FDS)
    bool created_file = false;   // this process bound the file (so it may unlink it)
    dev_t file_dev = 0;          // identity of the file it bound (to unlink only its own)
    ino_t file_ino = 0;
};

// Creates `options.path` as a listening AF_UNIX SOCK_STREAM socket:
//  - the parent directory must exist (it is not created);
//  - an existing socket file nobody listens on (connect() is refused) is a
//    stale leftover and is replaced; one that accepts connections is an error
//    ("already in use by another process"); any other kind of file is an error;
//  - the file gets `mode` (chmod) and `group` (chown; an unknown group is an
//    error naming it) before listen(), so no client connects earlier.
core::Result<ListeningSocket> listenUnix(const UnixListenOptions& options);

// The id of group `name` (getgrnam_r); kNotFound "PATH: unknown group 'NAME'"
// when there is none, kIo when the lookup itself failed. `path` names what the
// group is for in the message.
core::Result<gid_t> lookupGroup(const std::filesystem::path& path, const std::string& name);

// Socket activation (the sd_listen_fds protocol, without libsystemd): when
// LISTEN_PID is this process and LISTEN_FDS >= 1, adopts `first_fd` (3, or
// another number in tests) after checking that it is a listening AF_UNIX
// SOCK_STREAM socket, makes it non-blocking and close-on-exec (all passed
// descriptors become close-on-exec). Always unsets LISTEN_PID, LISTEN_FDS and
// LISTEN_FDNAMES, so children do not inherit them. Returns nullopt when the
// process was not socket-activated.
core::Result<std::optional<ListeningSocket>> takeActivatedSocket(int first_fd = 3);

// Checks that `fd` is a listening AF_UNIX SOCK_STREAM socket and makes it
// non-blocking and close-on-exec; the result owns `fd` (also on error).
core::Result<ListeningSocket> adoptListeningSocket(int fd);

// Removes the socket file of `socket` if this process created it and the path
// still names that same file (never when socket-activated). Returns whether it
// removed it.
bool removeSocketFile(const ListeningSocket& socket);

// Accepts one connection (non-blocking, close-on-exec). An invalid UniqueFd
// means "nothing to accept now" (EAGAIN, EINTR, or the peer already gone);
// an Error is a real failure (EMFILE, ENOBUFS, ...) naming `what`.
core::Result<base::UniqueFd> acceptClient(int listen_fd, const std::string& what);

// Connects to the UNIX stream socket at `path` (blocking connect, then the
// descriptor is close-on-exec; used by clients and tests).
core::Result<base::UniqueFd> connectUnix(const std::filesystem::path& path);

}  // namespace scaled::drivers::ipc
