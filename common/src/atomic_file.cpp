#include "dem/common/atomic_file.hpp"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <stdexcept>

#include <fcntl.h>
#include <unistd.h>

namespace dem {

int create_exclusive(const std::string& path) {
  if (::unlink(path.c_str()) != 0 && errno != ENOENT)
    throw std::runtime_error("cannot remove the old " + path + " (" + std::strerror(errno) + ")");
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0644);
  if (fd < 0)
    throw std::runtime_error("cannot create " + path + " (" + std::strerror(errno) +
                             "): check that the folder exists and is writable");
  return fd;
}

void write_part(const std::string& path, const std::string& content) {
  const std::string tmp = path + ".part";
  const int fd = create_exclusive(tmp);
  const char* p = content.data();
  std::size_t left = content.size();
  int err = 0;
  while (left > 0) {
    const ssize_t w = ::write(fd, p, left);
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) { err = w < 0 ? errno : ENOSPC; break; }
    p += w;
    left -= static_cast<std::size_t>(w);
  }
  if (::close(fd) != 0 && !err) err = errno;
  if (err)
    throw std::runtime_error("writing " + tmp + " failed (" + std::strerror(err) + (err == ENOSPC ? ": disk full" : "") +
                             "): " + path + " was not written; free space and run the command again (the incomplete " +
                             tmp + " is left behind)");
}

void commit_part(const std::string& path) {
  const std::string tmp = path + ".part";
  if (std::rename(tmp.c_str(), path.c_str()) != 0)
    throw std::runtime_error("cannot rename " + tmp + " to " + path + " (" + std::strerror(errno) + ")");
}

void write_file_atomic(const std::string& path, const std::string& content) {
  write_part(path, content);
  commit_part(path);
}

void write_files_atomic(const std::vector<std::pair<std::string, std::string>>& files) {
  for (const auto& [path, text] : files) write_part(path, text);
  for (const auto& [path, text] : files) commit_part(path);
}

}  // namespace dem
