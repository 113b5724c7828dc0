#include "demfit/table.hpp"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include <cerrno>
#include <cstring>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace demfit {

namespace {
std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> out;
  std::string cur;
  std::istringstream ls(line);
  while (std::getline(ls, cur, ',')) out.push_back(cur);
  if (!line.empty() && line.back() == ',') out.push_back("");
  return out;
}
// Every write and the close are checked: on a full disk only path.part is left.
void write_part(const std::string& path, const std::string& s) {
  const std::string tmp = path + ".part";
  // Created exclusively: a stale .part or a planted link is unlinked, never followed.
  if (::unlink(tmp.c_str()) != 0 && errno != ENOENT) throw std::runtime_error("cannot remove the old " + tmp);
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0644);
  if (fd < 0) throw std::runtime_error("cannot write " + tmp + " (" + std::strerror(errno) + ")");
  const char* p = s.data();
  std::size_t left = s.size();
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
                             "): " + path + " was not written (only the incomplete .part is left); free space and run again");
}
void commit_part(const std::string& path) {
  if (std::rename((path + ".part").c_str(), path.c_str()) != 0) throw std::runtime_error("cannot rename " + path + ".part");
}
std::string json_str(const std::string& s) {
  std::string o = "\"";
  for (char c : s) { if (c == '"' || c == '\\') o += '\\'; o += c; }
  return o + "\"";
}
bool is_number(const std::string& s) {
  if (s.empty()) return false;
  char* end = nullptr;
  std::strtod(s.c_str(), &end);
  return end && *end == 0 && s != "nan";
}
std::string tex_escape(const std::string& s) {
  std::string o;
  for (char c : s) {
    if (c == '_' || c == '%' || c == '&' || c == '#') o += '\\';
    o += c;
  }
  return o;
}
}  // namespace

const std::vector<double>& Table::column(const std::string& name) const {
  for (std::size_t k = 0; k < header.size(); ++k)
    if (header[k] == name) return numeric[k];
  throw std::runtime_error(source + ": no column '" + name + "'");
}

Table read_table(const std::string& path) {
  // A regular file only: a device (/dev/zero) or a FIFO would never end (opened without blocking).
  const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) throw std::runtime_error("cannot read " + path + " (" + std::strerror(errno) + ")");
  struct stat st {};
  const bool regular = ::fstat(fd, &st) == 0 && S_ISREG(st.st_mode);
  ::close(fd);
  if (!regular) throw std::runtime_error(path + " is not a regular file (a device, FIFO or folder): give a curve CSV");
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot read " + path);
  return parse_table(in, path);
}

Table parse_table(std::istream& in, const std::string& path) {
  Table t;
  t.source = path;
  std::string line;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    if (!line.empty() && line[0] == '#') t.comments.push_back(line);
    if (line.empty() || line[0] == '#') continue;
    auto cells = split(line);
    if (t.header.empty()) { t.header = cells; t.numeric.assign(cells.size(), {}); continue; }
    if (cells.size() != t.header.size())
      throw std::runtime_error(path + ":" + std::to_string(lineno) + ": " + std::to_string(cells.size()) +
                               " cells, header has " + std::to_string(t.header.size()));
    for (std::size_t k = 0; k < cells.size(); ++k) {
      char* end = nullptr;
      const double v = std::strtod(cells[k].c_str(), &end);
      t.numeric[k].push_back(end != cells[k].c_str() ? v : std::nan(""));
    }
    t.rows.push_back(std::move(cells));
  }
  if (t.header.empty()) throw std::runtime_error(path + ": no header line");
  return t;
}

void write_table_all(const Table& t, const std::string& stem, const std::string& caption) {
  std::ostringstream csv, js, md, tex;
  for (std::size_t k = 0; k < t.header.size(); ++k) csv << (k ? "," : "") << t.header[k];
  csv << "\n";
  for (auto& r : t.rows) {
    for (std::size_t k = 0; k < r.size(); ++k) {
      std::string cell = r[k];
      if (cell.find(',') != std::string::npos || cell.find('"') != std::string::npos) {
        std::string q = "\"";
        for (char c : cell) { if (c == '"') q += '"'; q += c; }
        cell = q + "\"";
      }
      csv << (k ? "," : "") << cell;
    }
    csv << "\n";
  }
  js << "{\n  \"caption\": " << json_str(caption) << ",\n  \"rows\": [";
  for (std::size_t i = 0; i < t.rows.size(); ++i) {
    js << (i ? ",\n    {" : "\n    {");
    for (std::size_t k = 0; k < t.header.size(); ++k)
      js << (k ? ", " : "") << json_str(t.header[k]) << ": "
         << (is_number(t.rows[i][k]) ? t.rows[i][k] : (t.rows[i][k] == "nan" ? "null" : json_str(t.rows[i][k])));
    js << "}";
  }
  js << "\n  ]\n}\n";
  md << "<!-- " << caption << " -->\n|";
  for (auto& h : t.header) md << " " << h << " |";
  md << "\n|";
  for (std::size_t k = 0; k < t.header.size(); ++k) md << "---|";
  md << "\n";
  for (auto& r : t.rows) {
    md << "|";
    for (auto& c : r) md << " " << c << " |";
    md << "\n";
  }
  tex << "% " << caption << "\n\\begin{tabular}{" << std::string(t.header.size(), 'l') << "}\n\\hline\n";
  for (std::size_t k = 0; k < t.header.size(); ++k) tex << (k ? " & " : "") << tex_escape(t.header[k]);
  tex << " \\\\\n\\hline\n";
  for (auto& r : t.rows) {
    for (std::size_t k = 0; k < r.size(); ++k) tex << (k ? " & " : "") << tex_escape(r[k]);
    tex << " \\\\\n";
  }
  tex << "\\hline\n\\end{tabular}\n";
  // All four or none: renamed into place only once every one is written.
  const std::pair<const char*, std::string> files[] = {{".csv", csv.str()}, {".json", js.str()}, {".md", md.str()}, {".tex", tex.str()}};
  for (const auto& [ext, text] : files) write_part(stem + ext, text);
  for (const auto& [ext, text] : files) commit_part(stem + ext);
}

std::string table_number(double v, int prec) {
  if (!std::isfinite(v)) return "nan";
  char b[64];
  std::snprintf(b, sizeof b, "%.*g", prec, v);
  return b;
}

void write_text_file(const std::string& path, const std::string& content) {
  write_part(path, content);
  commit_part(path);
}

}  // namespace demfit
