// The sculpting window's input scripts (apps/sculpt/input_script): the keys an event may hold
// are one table (kScriptKeys) that the parser reads and docs/user-guide.md's two Input scripts
// tables list, with the same units, ranges and defaults; the parser checks each number
// against the table's range and takes its defaults; a key outside it is refused, naming it.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <set>
#include <sstream>

#include "isotouch/tests/doc_tables.h"
#include "isotouch/apps/sculpt/input_script.h"
#include "isotouch/io/scene_field_range.h"

namespace isotouch::sculpt {
namespace {

// A documented field's unit, range and default cells ("" where the table has no such column).
using DocRow = std::array<std::string, 3>;

// The rows of the table after `anchor`, by key ("action: " before an action's).
void read_table(const std::string& doc, const std::string& anchor, const std::string& prefix,
                std::map<std::string, DocRow>& rows) {
  const auto table = test::table_after(doc, anchor);
  ASSERT_GE(table.size(), 2u) << "no table after '" << anchor << "'";
  const auto cell = [&](const std::vector<std::string>& row, const std::string& name) {
    for (std::size_t c = 0; c < table[0].size() && c < row.size(); ++c)
      if (table[0][c] == name) return row[c];
    return std::string();
  };
  for (std::size_t i = 1; i < table.size(); ++i)
    for (const auto& n : test::code_names(table[i][0]))
      rows[prefix + n] = {cell(table[i], "unit"), cell(table[i], "range"), cell(table[i], "default")};
}

// The docs' two tables list exactly kScriptKeys, each field with its unit, range and default
// and each action with its range: a key added or a range changed on one side fails here.
TEST(InputScriptDocs, TablesListExactlyTheParsersKeys) {
  const std::string doc = test::user_guide();
  ASSERT_FALSE(doc.empty()) << "docs/user-guide.md not found";
  std::map<std::string, DocRow> documented, table;
  read_table(doc, "`--script FILE` drives the window", "", documented);
  read_table(doc, "The actions (", "action: ", documented);
  for (const ScriptKey& k : kScriptKeys)
    table[(k.action ? "action: " : "") + std::string(k.name)] =
        k.action ? DocRow{"", std::string(k.range), ""}
                 : DocRow{std::string(k.unit), std::string(k.range), std::string(k.default_text)};
  for (const auto& [key, row] : table) {
    const auto d = documented.find(key);
    if (d == documented.end()) ADD_FAILURE() << key << ": in kScriptKeys but not in docs/user-guide.md";
    else EXPECT_EQ(d->second, row) << key << ": docs/user-guide.md against kScriptKeys";
  }
  for (const auto& [key, row] : documented) EXPECT_TRUE(table.count(key)) << key << ": documented but not in kScriptKeys";
}

// The parser refuses and accepts at kScriptKeys' ranges, whatever they are: each end and
// just beyond it, read from the table.
TEST(InputScriptDocs, ParserChecksTheTablesRanges) {
  const std::pair<std::string_view, std::string> cases[] = {
      {"after_frames", R"({"quit": true, "after_frames": V})"}, {"radius_mm", R"({"tool": "carve", "radius_mm": V})"},
      {"strength", R"({"tool": "carve", "strength": V})"},      {"timeout_s", R"({"wait": "edits", "timeout_s": V})"},
      {"cursor", R"({"cursor": [0.5, V]})"},                    {"zoom", R"({"zoom": V})"},
      {"resize", R"({"resize": [V, 100]})"}};
  int checked = 0;
  for (const auto& [key, event] : cases) {
    const ScriptKey* k = nullptr;
    for (const ScriptKey& s : kScriptKeys)
      if (s.name == key) k = &s;
    ASSERT_TRUE(k) << key;
    const auto range = io::field_range(k->range);
    ASSERT_TRUE(range) << key << ": '" << k->range << "'";
    const auto accepts = [&, &event = event](double v) {
      std::ostringstream num;
      num.precision(17);
      num << v;
      std::string e = event;
      e.replace(e.find('V'), 1, num.str());
      try {
        parse_input_script(R"({"events": [)" + e + "]}", "s.json");
        return true;
      } catch (const ScriptError& err) {
        EXPECT_NE(std::string(err.what()).find("field '" + std::string(key) + "' must be " + range->phrase()),
                  std::string::npos) << err.what();
        return false;
      }
    };
    const double step = range->integer ? 1 : 1e-6;
    EXPECT_EQ(accepts(range->lo), !range->lo_open) << key << " = " << range->lo;
    EXPECT_FALSE(accepts(range->lo - step)) << key << " = " << range->lo - step;
    EXPECT_TRUE(accepts(range->lo + step)) << key << " = " << range->lo + step;
    if (std::isfinite(range->hi)) {
      EXPECT_EQ(accepts(range->hi), !range->hi_open) << key << " = " << range->hi;
      EXPECT_FALSE(accepts(range->hi + step)) << key << " = " << range->hi + step;
    }
    ++checked;
  }
  // Every key with a numeric range is among the cases.
  for (const ScriptKey& k : kScriptKeys) {
    if (!io::field_range(k.range)) continue;
    EXPECT_TRUE(std::any_of(std::begin(cases), std::end(cases), [&](const auto& c) { return c.first == k.name; }))
        << k.name;
  }
  EXPECT_EQ(checked, 7);
}

// A key left out takes kScriptKeys' default: every numeric default, read back from an event.
TEST(InputScriptDocs, AbsentKeysTakeTheTablesDefaults) {
  const InputEvent ev = parse_input_script(R"({"events": [{"quit": true}]})", "s.json").at(0);
  const std::map<std::string, double> parsed{{"after_frames", ev.after_frames}, {"timeout_s", ev.timeout_s}};
  for (const ScriptKey& k : kScriptKeys) {
    const auto def = io::plain_number(k.default_text);
    if (!def) continue;
    const auto it = parsed.find(std::string(k.name));
    if (it == parsed.end()) ADD_FAILURE() << k.name << ": a numeric default this test does not read back";
    else EXPECT_EQ(it->second, *def) << k.name;
  }
}

TEST(InputScriptDocs, ParserRefusesAKeyOutsideTheTable) {
  try {
    parse_input_script(R"({"events": [{"cursor": [0.5, 0.5], "colour": 1}]})", "s.json");
    FAIL() << "accepted an unknown key";
  } catch (const ScriptError& e) {
    EXPECT_NE(std::string(e.what()).find("s.json: event 0: unknown field 'colour'"), std::string::npos) << e.what();
  }
  // Every action in the table is parsed as one (two in one event are refused as such).
  try {
    parse_input_script(R"({"events": [{"cursor": [0.5, 0.5], "quit": true}]})", "s.json");
    FAIL() << "accepted two actions";
  } catch (const ScriptError& e) {
    EXPECT_NE(std::string(e.what()).find("needs exactly one action (cursor, press"), std::string::npos) << e.what();
  }
  EXPECT_EQ(parse_input_script(R"({"events": [{"preset": "bone"}]})", "s.json").at(0).text, "bone");
}

}  // namespace
}  // namespace isotouch::sculpt
