#include "isotouch/io/output_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <climits>
#include <cstdlib>
#include <cstring>
#include <filesystem>

namespace isotouch::io {
namespace {

namespace fs = std::filesystem;

std::string os_error(const std::string& path, const std::string& what, int err) {
  return path + ": " + what + ": " + std::strerror(err);
}

/// Closes a descriptor on every path out of a scope.
struct Fd {
  int fd = -1;
  explicit Fd(int f) : fd(f) {}
  Fd(const Fd&) = delete;
  Fd& operator=(const Fd&) = delete;
  ~Fd() {
    if (fd >= 0) ::close(fd);
  }
  /// Closes now and reports a failed close (data lost on some file systems).
  int close_checked() {
    const int rc = ::close(fd);
    fd = -1;
    return rc;
  }
};

/// Removes a file on every path out of a scope unless released.
struct Unlinker {
  std::string path;
  ~Unlinker() {
    if (!path.empty()) ::unlink(path.c_str());
  }
};

const char* kind_of(mode_t m) {
  if (S_ISDIR(m)) return "a directory";
  if (S_ISBLK(m)) return "a block device";
  if (S_ISSOCK(m)) return "a socket";
  return "not a regular file, a character device or a FIFO";
}

/// Copies the bytes of the open descriptor `in` (read from its start) to `to` (the output `path`).
void copy_fd(int in, int to, const std::string& path) {
  std::array<char, 1 << 16> buf{};
  for (off_t at = 0;;) {
    const ssize_t n = ::pread(in, buf.data(), buf.size(), at);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) throw OutputError(os_error(path, "reading the finished output back failed", errno));
    if (n == 0) return;
    write_all(to, buf.data(), std::size_t(n), path);
    at += n;
  }
}

/// Copies the bytes of the file `from` to the open descriptor `to` (the output `path`).
void copy_into(const std::string& from, int to, const std::string& path) {
  Fd in(::open(from.c_str(), O_RDONLY | O_CLOEXEC));
  if (in.fd < 0) throw OutputError(os_error(from, "cannot read back the finished output", errno));
  copy_fd(in.fd, to, path);
}

void fsync_file(const std::string& file) {
  Fd fd(::open(file.c_str(), O_RDONLY | O_CLOEXEC));
  if (fd.fd < 0 || ::fsync(fd.fd) != 0) throw OutputError(os_error(file, "fsync failed", errno));
}

void fsync_folder(const std::string& dir) {
  Fd fd(::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC));
  if (fd.fd >= 0) (void)::fsync(fd.fd);  // the rename's durability; the file is whole either way
}

std::string folder_of(const std::string& path) {
  const fs::path p = fs::path(path).parent_path();
  return p.empty() ? std::string(".") : p.string();
}

/// The extension a writer may pick its format by (".nii.gz", ".vdb", ...; "" for none):
/// temp files end in it too.
std::string format_suffix(const std::string& path) {
  const fs::path name = fs::path(path).filename();
  std::string ext = name.extension().string();
  if (ext == ".gz") ext = name.stem().extension().string() + ext;
  return ext.size() <= 16 ? ext : std::string();
}

/// The process's umask (read once: umask(2) can only be read by setting it).
mode_t current_umask() {
  static const mode_t mask = [] {
    const mode_t m = ::umask(022);
    ::umask(m);
    return m;
  }();
  return mask;
}

/// A fresh empty file from `tmpl` (XXXXXX followed by `suffix`), readable like an ordinary output.
std::string make_temp(std::string tmpl, const std::string& for_path, const std::string& suffix = "") {
  tmpl += suffix;
  const int fd = ::mkstemps(tmpl.data(), int(suffix.size()));
  if (fd < 0) throw OutputError(os_error(for_path, "cannot create a temp file '" + tmpl + "'", errno));
  ::fchmod(fd, 0666 & ~current_umask());  // mkstemp makes 0600; outputs are ordinary files, as the umask says
  ::close(fd);
  return tmpl;
}

std::string temp_beside(const std::string& resolved, bool keep_extension = false) {
  const std::string dir = folder_of(resolved);
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw OutputError(resolved + ": cannot write: folder '" + dir + "' does not exist");
  return make_temp(resolved + ".tmp-" + std::to_string(::getpid()) + "-XXXXXX", resolved,
                   keep_extension ? format_suffix(resolved) : std::string());
}

std::string temp_elsewhere(const std::string& for_path, bool keep_extension = false) {
  std::error_code ec;
  fs::path dir = fs::temp_directory_path(ec);
  if (ec) dir = "/tmp";
  return make_temp((dir / ("isotouch-output-" + std::to_string(::getpid()) + "-XXXXXX")).string(), for_path,
                   keep_extension ? format_suffix(for_path) : std::string());
}

/// Renames the finished temp `tmp` (in the target's folder) over `t.resolved`.
void commit_replace(const std::string& tmp, const OutputTarget& t) {
  fsync_file(tmp);
  if (::rename(tmp.c_str(), t.resolved.c_str()) != 0)
    throw OutputError(os_error(t.requested, "cannot rename '" + tmp + "' into place", errno));
  fsync_folder(folder_of(t.resolved));
}

/// Writes the finished content (open descriptor `in`) into the stream `t`, in place.
void commit_stream(int in, const OutputTarget& t) {
  if (t.fd >= 0) {
    copy_fd(in, t.fd, t.fd == STDERR_FILENO ? "standard error" : "standard output");
    return;
  }
  Fd out(::open(t.resolved.c_str(), O_WRONLY | O_CLOEXEC | O_NOCTTY));
  if (out.fd < 0) throw OutputError(os_error(t.requested, "cannot open for writing", errno));
  copy_fd(in, out.fd, t.requested);
  if (out.close_checked() != 0) throw OutputError(os_error(t.requested, "close failed", errno));
}

/// commit_stream of a finished file, removed from its folder before the copy starts: a
/// process killed while it waits for a FIFO's reader leaves no temp file behind.
void commit_stream_file(const std::string& tmp, const OutputTarget& t) {
  Fd in(::open(tmp.c_str(), O_RDONLY | O_CLOEXEC));
  if (in.fd < 0) throw OutputError(os_error(tmp, "cannot read back the finished output", errno));
  ::unlink(tmp.c_str());
  commit_stream(in.fd, t);
}

/// The name a dangling symlink chain (or a plain missing path) ends in.
std::string follow_to_missing(const std::string& path) {
  fs::path p = path;
  for (int hop = 0; hop <= 40; ++hop) {
    struct stat st {};
    if (::lstat(p.c_str(), &st) != 0 || !S_ISLNK(st.st_mode)) return p.string();
    std::error_code ec;
    const fs::path to = fs::read_symlink(p, ec);
    if (ec) throw OutputError(path + ": cannot read the symlink '" + p.string() + "': " + ec.message());
    p = to.is_absolute() ? to : p.parent_path() / to;
  }
  throw OutputError(path + ": cannot write an output here: too many levels of symbolic links");
}

}  // namespace

void write_all(int fd, const char* data, std::size_t size, const std::string& path) {
  for (std::size_t done = 0; done < size;) {
    const ssize_t n = ::write(fd, data + done, size - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) throw OutputError(os_error(path, "write failed", n < 0 ? errno : EIO));
    done += std::size_t(n);
  }
}


OutputTarget classify_output(const std::string& path) {
  if (path.empty()) throw OutputError("output path is empty");
  if (path == "-") return {path, "-", OutputKind::kStream, STDOUT_FILENO};
  struct stat st {};
  if (::stat(path.c_str(), &st) == 0) {  // follows every symlink
    for (const int fd : {STDOUT_FILENO, STDERR_FILENO}) {  // e.g. /dev/stdout while stdout is a log file
      struct stat sf {};
      if (::fstat(fd, &sf) == 0 && sf.st_dev == st.st_dev && sf.st_ino == st.st_ino)
        return {path, "-", OutputKind::kStream, fd};
    }
    if (S_ISCHR(st.st_mode) || S_ISFIFO(st.st_mode)) return {path, path, OutputKind::kStream};
    if (!S_ISREG(st.st_mode))
      throw OutputError(path + ": cannot write an output here: it is " + kind_of(st.st_mode) +
                        " (only a regular file, a new file, a character device, a FIFO or - are written)");
    char real[PATH_MAX];
    if (::realpath(path.c_str(), real) == nullptr) throw OutputError(os_error(path, "cannot resolve the path", errno));
    return {path, real, OutputKind::kReplace};
  }
  const int err = errno;
  if (err == ELOOP) throw OutputError(path + ": cannot write an output here: too many levels of symbolic links");
  if (err != ENOENT) throw OutputError(os_error(path, "cannot write an output here", err));
  return {path, follow_to_missing(path), OutputKind::kReplace};
}

void write_output(const std::string& path, const std::function<void(const std::string& file)>& fill,
                  bool keep_extension) {
  const OutputTarget t = classify_output(path);
  Unlinker tmp{t.kind == OutputKind::kReplace ? temp_beside(t.resolved, keep_extension)
                                              : temp_elsewhere(path, keep_extension)};
  fill(tmp.path);
  if (t.kind == OutputKind::kReplace) {
    commit_replace(tmp.path, t);
    tmp.path.clear();  // renamed: nothing left to remove
  } else {
    const std::string done = tmp.path;
    tmp.path.clear();
    commit_stream_file(done, t);
  }
}

void write_output(const std::string& path, std::string_view content) {
  write_output(path, [&](const std::string& file) {
    Fd fd(::open(file.c_str(), O_WRONLY | O_TRUNC | O_CLOEXEC));
    if (fd.fd < 0) throw OutputError(os_error(file, "cannot open for writing", errno));
    write_all(fd.fd, content.data(), content.size(), path);
    if (fd.close_checked() != 0) throw OutputError(os_error(path, "close failed", errno));
  });
}

void place_output(const std::string& done, const std::string& path) {
  Unlinker finished{done};
  const OutputTarget t = classify_output(path);
  if (t.kind == OutputKind::kStream) {
    finished.path.clear();
    commit_stream_file(done, t);
    return;
  }
  std::error_code ec;
  if (fs::equivalent(folder_of(done), folder_of(t.resolved), ec)) {
    commit_replace(done, t);
    finished.path.clear();
    return;
  }
  Unlinker copy{temp_beside(t.resolved)};
  {
    Fd out(::open(copy.path.c_str(), O_WRONLY | O_TRUNC | O_CLOEXEC));
    if (out.fd < 0) throw OutputError(os_error(copy.path, "cannot open for writing", errno));
    copy_into(done, out.fd, path);
    if (out.close_checked() != 0) throw OutputError(os_error(path, "close failed", errno));
  }
  commit_replace(copy.path, t);
  copy.path.clear();
}

}  // namespace isotouch::io
