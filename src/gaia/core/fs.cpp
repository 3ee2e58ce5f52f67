#include "gaia/core/fs.h"

#include <fcntl.h>
#include <signal.h>
#include <stdio.h>
#include <sys/file.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <regex>
#include <sstream>

#include "gaia/core/error.h"

namespace gaia {

std::string unique_suffix() {
  static std::atomic<uint64_t> counter{0};
  return fmt::format("{}-{}", static_cast<long>(::getpid()), counter.fetch_add(1));
}

std::string read_file(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) fail("{}: cannot open file ({})", path.string(), std::strerror(errno));
  std::ostringstream ss;
  ss << in.rdbuf();
  if (in.bad()) fail("{}: read error", path.string());
  return ss.str();
}

std::vector<std::string> read_lines(const fs::path& p) {
  std::string text = read_file(p);
  std::vector<std::string> lines;
  size_t start = 0;
  while (start < text.size()) {
    size_t nl = text.find('\n', start);
    if (nl == std::string::npos) nl = text.size();
    lines.push_back(text.substr(start, nl - start));
    start = nl + 1;
  }
  return lines;
}

void write_file_atomic(const fs::path& path, std::string_view bytes) {
  if (path.has_parent_path()) fs::create_directories(path.parent_path());
  fs::path tmp = path;
  tmp += ".tmp-" + unique_suffix();
  int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  if (fd < 0) fail("{}: cannot create file ({})", path.string(), std::strerror(errno));
  size_t off = 0;
  while (off < bytes.size()) {
    ssize_t w = ::write(fd, bytes.data() + off, bytes.size() - off);
    if (w < 0) {
      if (errno == EINTR) continue;
      int e = errno;
      ::close(fd);
      ::unlink(tmp.c_str());
      fail("{}: write failed ({})", path.string(), std::strerror(e));
    }
    off += static_cast<size_t>(w);
  }
  // A full disk may only show at fsync or close (NFS, some file systems): neither may pass unnoticed.
  if (::fsync(fd) != 0 && errno != EINVAL) {
    int e = errno;
    ::close(fd);
    ::unlink(tmp.c_str());
    fail("{}: write failed ({})", path.string(), std::strerror(e));
  }
  if (::close(fd) != 0) {
    int e = errno;
    ::unlink(tmp.c_str());
    fail("{}: write failed ({})", path.string(), std::strerror(e));
  }
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    int e = errno;
    ::unlink(tmp.c_str());
    fail("{}: cannot rename temporary file into place ({})", path.string(), std::strerror(e));
  }
}

StagingDir::StagingDir(fs::path final_path) : final_(std::move(final_path)) {
  fs::path parent = final_.has_parent_path() ? final_.parent_path() : fs::path(".");
  fs::create_directories(parent);
  tmp_ = parent / (".tmp-" + final_.filename().string() + "-" + unique_suffix());
  fs::create_directories(tmp_);
}

StagingDir::~StagingDir() {
  if (!committed_) {
    std::error_code ec;
    fs::remove_all(tmp_, ec);
  }
}

void StagingDir::commit(bool overwrite) {
  if (fs::exists(final_)) {
    if (!overwrite) fail("{}: already exists (refusing to overwrite)", final_.string());
    // renameat2(RENAME_EXCHANGE) swaps the two names at once; the old content then sits at tmp_.
    if (::renameat2(AT_FDCWD, tmp_.c_str(), AT_FDCWD, final_.c_str(), RENAME_EXCHANGE) == 0) {
      committed_ = true;
      std::error_code ec;
      fs::remove_all(tmp_, ec);
      return;
    }
    // File systems without the exchange: two renames. A kill between them leaves both copies on disk, complete,
    // and the readers (train/checkpoint.h recover_checkpoint) put the newest back.
    fs::path old = final_;
    old += ".old-" + unique_suffix();
    fs::rename(final_, old);
    fs::rename(tmp_, final_);
    fs::remove_all(old);
  } else {
    fs::rename(tmp_, final_);
  }
  committed_ = true;
}

long temporary_owner(const std::string& name) {
  // unique_suffix() ends a name with "-PID-N" (".tmp-x-PID-N", maybe + an extension such as ".mp4") or
  // ".tmp-PID-N" / ".old-PID-N" after a file name.
  static const std::regex re(R"((?:^\.tmp-.*-|\.tmp-|\.old-)([0-9]+)-[0-9]+(?:\.[A-Za-z0-9]{1,5})?$)");
  std::smatch m;
  if (!std::regex_search(name, m, re)) return 0;
  try {
    return std::stol(m[1].str());
  } catch (const std::exception&) {
    return 0;
  }
}

bool process_alive(long pid) { return pid > 0 && (::kill(static_cast<pid_t>(pid), 0) == 0 || errno == EPERM); }

int remove_stale_temporaries(const fs::path& dir) {
  int removed = 0;
  std::error_code ec;
  for (auto it = fs::directory_iterator(dir, ec); !ec && it != fs::directory_iterator(); it.increment(ec)) {
    const long pid = temporary_owner(it->path().filename().string());
    if (pid == 0 || pid == static_cast<long>(::getpid()) || process_alive(pid)) continue;
    std::error_code rm;
    fs::remove_all(it->path(), rm);
    if (!rm) ++removed;
  }
  return removed;
}

DirLock::DirLock(const fs::path& dir) : dir_(dir) {
  created_ = !fs::exists(dir);
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) fail("{}: cannot create directory ({})", dir.string(), ec.message());
  const fs::path lock = dir / ".lock";
  fd_ = ::open(lock.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd_ < 0) fail("{}: cannot create lock file ({})", lock.string(), std::strerror(errno));
  if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
    const int e = errno;
    char buf[32] = {};
    const ssize_t n = ::pread(fd_, buf, sizeof buf - 1, 0);
    ::close(fd_);
    fd_ = -1;
    if (e == EWOULDBLOCK)
      fail("{}: another gaia run (pid {}) is using this directory; wait for it or choose another --out", dir.string(),
           n > 0 ? std::string(buf, static_cast<size_t>(n)).substr(0, std::string(buf).find('\n')) : "?");
    fail("{}: cannot lock ({})", lock.string(), std::strerror(e));
  }
  const std::string pid = std::to_string(::getpid()) + "\n";
  if (::ftruncate(fd_, 0) == 0) (void)!::pwrite(fd_, pid.data(), pid.size(), 0);
}

DirLock::~DirLock() {
  if (fd_ < 0) return;
  std::error_code ec;
  if (created_) {
    bool only_lock = true;
    for (auto it = fs::directory_iterator(dir_, ec); !ec && it != fs::directory_iterator(); it.increment(ec))
      if (it->path().filename() != ".lock") only_lock = false;
    if (!ec && only_lock) {
      fs::remove(dir_ / ".lock", ec);
      fs::remove(dir_, ec);
    }
  }
  ::close(fd_);
}

MappedFile::MappedFile(const fs::path& path) : path_(path) {
  int fd = ::open(path.c_str(), O_RDONLY);
  if (fd < 0) fail("{}: cannot open file ({})", path.string(), std::strerror(errno));
  struct stat st {};
  if (::fstat(fd, &st) != 0) {
    ::close(fd);
    fail("{}: cannot stat file", path.string());
  }
  size_ = static_cast<size_t>(st.st_size);
  if (size_ > 0) {
    void* p = ::mmap(nullptr, size_, PROT_READ, MAP_PRIVATE, fd, 0);
    if (p == MAP_FAILED) {
      ::close(fd);
      fail("{}: mmap failed ({})", path.string(), std::strerror(errno));
    }
    data_ = static_cast<const uint8_t*>(p);
  }
  ::close(fd);
}

MappedFile::~MappedFile() {
  if (data_) ::munmap(const_cast<uint8_t*>(data_), size_);
}

}  // namespace gaia
