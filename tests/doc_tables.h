// doc_tables.h - Markdown tables read out of docs/user-guide.md, for the tests that hold a
// parser's table of fields against the manual's.
#pragma once
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace isotouch::test {

/// docs/user-guide.md's text ("" if it cannot be read).
inline std::string user_guide() {
  std::ifstream f(std::string(ISOTOUCH_TEST_DATA) + "/../docs/user-guide.md");
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

/// The rows of the first Markdown table after the first line of `doc` that starts with
/// `anchor`: each row's cells, trimmed.
inline std::vector<std::vector<std::string>> table_after(const std::string& doc, const std::string& anchor) {
  std::istringstream in(doc);
  std::string line;
  bool found = false, in_table = false;
  std::vector<std::vector<std::string>> rows;
  while (std::getline(in, line)) {
    if (!found) {
      found = line.rfind(anchor, 0) == 0;
      continue;
    }
    if (line.rfind("|", 0) != 0) {
      if (in_table) break;
      continue;
    }
    in_table = true;
    std::vector<std::string> cells;
    std::string cell;
    for (std::size_t i = 1; i < line.size(); ++i) {
      if (line[i] == '|' && line[i - 1] != '\\') {
        const auto b = cell.find_first_not_of(' '), e = cell.find_last_not_of(' ');
        cells.push_back(b == std::string::npos ? "" : cell.substr(b, e - b + 1));
        cell.clear();
      } else {
        cell += line[i];
      }
    }
    if (cells.empty() || cells[0].rfind("---", 0) == 0) continue;
    rows.push_back(cells);
  }
  return rows;
}

/// The `name`s written in a cell ("`a`, `b`" -> a, b).
inline std::vector<std::string> code_names(const std::string& cell) {
  std::vector<std::string> names;
  for (std::size_t i = cell.find('`'); i != std::string::npos; i = cell.find('`', i + 1)) {
    const std::size_t j = cell.find('`', i + 1);
    if (j == std::string::npos) break;
    names.push_back(cell.substr(i + 1, j - i - 1));
    i = j;
  }
  return names;
}

}  // namespace isotouch::test
