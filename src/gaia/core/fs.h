#pragma once
// File helpers whose job is "no lost or half-written output": every file is written to a temporary
// sibling and renamed into place, so a crash leaves either the old file or the new one, never a torn one.
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

namespace gaia {

namespace fs = std::filesystem;

// Reads a whole file; throws gaia::Error naming the path if it is missing or unreadable.
std::string read_file(const fs::path& path);
// Its lines, split at '\n' (a last line without one counts; nothing is trimmed).
std::vector<std::string> read_lines(const fs::path& path);

// Writes bytes to `path` atomically (temp file in the same directory, fsync, rename).
void write_file_atomic(const fs::path& path, std::string_view bytes);

// A temporary directory next to `final_path` that becomes `final_path` on commit(); removed otherwise.
class StagingDir {
 public:
  explicit StagingDir(fs::path final_path);
  ~StagingDir();
  StagingDir(const StagingDir&) = delete;
  StagingDir& operator=(const StagingDir&) = delete;
  const fs::path& path() const { return tmp_; }
  // Replaces any existing final_path (only if `overwrite`), then renames the staging dir into place. The swap is one
  // atomic exchange where the file system allows it, so no instant lacks final_path.
  void commit(bool overwrite = false);

 private:
  fs::path final_, tmp_;
  bool committed_ = false;
};

// Read-only memory map of a file (POSIX mmap); the mapping lives as long as the object.
class MappedFile {
 public:
  explicit MappedFile(const fs::path& path);
  ~MappedFile();
  MappedFile(const MappedFile&) = delete;
  MappedFile& operator=(const MappedFile&) = delete;
  const uint8_t* data() const { return data_; }
  size_t size() const { return size_; }
  const fs::path& path() const { return path_; }

 private:
  fs::path path_;
  const uint8_t* data_ = nullptr;
  size_t size_ = 0;
};

// A unique suffix for temporary names (pid + counter), so concurrent writers never collide.
std::string unique_suffix();

// The pid inside a temporary name made with unique_suffix() (".tmp-x-PID-N[.ext]", "x.tmp-PID-N", "x.old-PID-N"), or 0.
long temporary_owner(const std::string& name);

// True while process `pid` exists.
bool process_alive(long pid);

// Removes the entries of `dir` that are temporaries (names from unique_suffix()) of processes no longer alive: what a
// kill leaves behind. Returns how many it removed.
int remove_stale_temporaries(const fs::path& dir);

// An exclusive lock on a directory (flock on DIR/.lock) for the life of the object. The kernel drops it when the
// process dies, so a kill never leaves a stale lock. A second holder fails at once, naming the first one's pid.
// A directory the lock created and that holds nothing else when the lock is released is removed again.
class DirLock {
 public:
  explicit DirLock(const fs::path& dir);
  ~DirLock();
  DirLock(const DirLock&) = delete;
  DirLock& operator=(const DirLock&) = delete;

 private:
  fs::path dir_;
  int fd_ = -1;
  bool created_ = false;
};

}  // namespace gaia
