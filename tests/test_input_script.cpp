// The sculpting window's input scripts (apps/sculpt/input_script): the keys an event may hold
// are one table (kScriptKeys) that the parser reads and docs/user-guide.md's two Input scripts
// tables list, with the same units; a key outside it is refused, naming it.
#include <gtest/gtest.h>

#include <map>
#include <set>

#include "isotouch/tests/doc_tables.h"
#include "isotouch/apps/sculpt/input_script.h"

namespace isotouch::sculpt {
namespace {

TEST(InputScriptDocs, TablesListExactlyTheParsersKeys) {
  const std::string doc = test::user_guide();
  ASSERT_FALSE(doc.empty()) << "docs/user-guide.md not found";
  const auto fields = test::table_after(doc, "`--script FILE` drives the window");
  const auto actions = test::table_after(doc, "| action | value | meaning |");
  ASSERT_GE(fields.size(), 2u);
  ASSERT_GE(actions.size(), 1u);
  ASSERT_EQ(fields[0][0], "field");
  ASSERT_EQ(fields[0][1], "unit");
  std::map<std::string, std::string> doc_fields;  // name -> unit
  for (std::size_t i = 1; i < fields.size(); ++i)
    for (const auto& n : test::code_names(fields[i][0])) doc_fields[n] = fields[i][1];
  std::set<std::string> doc_actions, table_fields, table_actions, doc_field_names;
  for (const auto& row : actions)
    for (const auto& n : test::code_names(row[0])) doc_actions.insert(n);
  for (const auto& [n, u] : doc_fields) doc_field_names.insert(n);
  for (const ScriptKey& k : kScriptKeys) (k.action ? table_actions : table_fields).insert(std::string(k.name));
  EXPECT_EQ(doc_field_names, table_fields) << "the docs' fields table and the parser's fields differ";
  EXPECT_EQ(doc_actions, table_actions) << "the docs' actions table and the parser's actions differ";
  for (const ScriptKey& k : kScriptKeys)
    if (!k.action && doc_fields.count(std::string(k.name))) EXPECT_EQ(doc_fields[std::string(k.name)], k.unit) << k.name;
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
