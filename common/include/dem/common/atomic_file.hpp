// The one atomic writer of the C++ side (sim/ and fit/; Python: demkit/atomic.py): PATH is written
// as PATH.part, created exclusively (a stale .part or a planted symbolic link is unlinked, never
// followed), every write and the close checked, then renamed onto PATH, so a file that exists is
// complete. On a full disk only the .part is left, and the error says so ("disk full").
#pragma once
#include <string>
#include <utility>
#include <vector>

namespace dem {

/// Creates PATH for writing, exclusively (whatever is there is unlinked first; O_CREAT | O_EXCL |
/// O_NOFOLLOW). Returns the file descriptor; throws std::runtime_error naming the file.
int create_exclusive(const std::string& path);

/// Writes PATH.part (create_exclusive, every write checked). Throws std::runtime_error.
void write_part(const std::string& path, const std::string& content);

/// Renames PATH.part onto PATH. Throws std::runtime_error.
void commit_part(const std::string& path);

/// write_part, then commit_part.
void write_file_atomic(const std::string& path, const std::string& content);

/// Several files, all or none: every .part is written before any is renamed into place.
void write_files_atomic(const std::vector<std::pair<std::string, std::string>>& files);

}  // namespace dem
