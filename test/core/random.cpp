// paps::Random gives the same numbers on every platform; these tests keep it so, and keep the
// tree free of calls that would hand its draws to a compiler-chosen order.
#include <paps/core/random.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace core_random_test {

TEST(Random, TheStreamIsSplitMix64) {
  // SplitMix64's published first output for the state 0.
  paps::Random rng(0);
  EXPECT_EQ(rng.next(), 0xe220a8397b1dcdafULL);
}

TEST(Random, VectorDrawsTakeZThenYThenX) {
  // The order GCC gave `Vector3d(gaussian(), gaussian(), gaussian())` before the helpers
  // existed; seeded test and bench data depend on it.
  for (std::uint64_t seed : {1u, 2u, 99u}) {
    paps::Random a(seed), b(seed);
    const Eigen::Vector3d g = a.gaussian3();
    const double gz = b.gaussian(), gy = b.gaussian(), gx = b.gaussian();
    EXPECT_EQ(g, Eigen::Vector3d(gx, gy, gz));
    const Eigen::Vector3d u = a.uniform3(-2, 3);
    const double uz = b.uniform(-2, 3), uy = b.uniform(-2, 3), ux = b.uniform(-2, 3);
    EXPECT_EQ(u, Eigen::Vector3d(ux, uy, uz));
    EXPECT_EQ(a.next(), b.next());
  }
}

// ---------------------------------------------------------------- the tree check

/// The source with comments, string and character literals blanked (newlines kept).
std::string blankCommentsAndLiterals(const std::string& s) {
  std::string out = s;
  for (std::size_t i = 0; i < s.size();) {
    if (s.compare(i, 2, "//") == 0) {
      while (i < s.size() && s[i] != '\n') out[i++] = ' ';
    } else if (s.compare(i, 2, "/*") == 0) {
      const std::size_t end = s.find("*/", i + 2);
      const std::size_t stop = end == std::string::npos ? s.size() : end + 2;
      for (; i < stop; ++i)
        if (s[i] != '\n') out[i] = ' ';
    } else if (s[i] == '"' || s[i] == '\'') {
      const char quote = s[i];
      for (out[i++] = ' '; i < s.size() && s[i] != quote && s[i] != '\n'; ++i) {
        if (s[i] == '\\' && i + 1 < s.size()) out[i++] = ' ';
        out[i] = ' ';
      }
      if (i < s.size() && s[i] == quote) out[i++] = ' ';
    } else {
      ++i;
    }
  }
  return out;
}

/// Random draws in a piece of code: `x.uniform(`, `x->gaussian(`, ... of paps::Random, and
/// `name(rng)` (a std distribution called on a generator named rng).
int countDraws(const std::string& code) {
  static const char* const kMethods[] = {"uniform", "gaussian", "below", "next", "uniform3", "gaussian3"};
  int n = 0;
  for (std::size_t i = 0; i < code.size(); ++i) {
    if (code[i] != '(') continue;
    std::size_t e = i;
    while (e > 0 && code[e - 1] == ' ') --e;
    std::size_t b = e;
    while (b > 0 && (std::isalnum(static_cast<unsigned char>(code[b - 1])) || code[b - 1] == '_')) --b;
    const std::string name = code.substr(b, e - b);
    std::size_t before = b;
    while (before > 0 && code[before - 1] == ' ') --before;
    const bool member = before > 0 && (code[before - 1] == '.' || (before > 1 && code.compare(before - 2, 2, "->") == 0));
    bool method = false;
    for (const char* m : kMethods) method = method || name == m;
    // `name(rng)`: the argument list is exactly `rng`, spaces aside.
    const std::size_t close = code.find(')', i);
    std::string argument = close == std::string::npos ? "" : code.substr(i + 1, close - i - 1);
    argument.erase(std::remove(argument.begin(), argument.end(), ' '), argument.end());
    const bool on_rng = argument == "rng";
    if ((member && method) || (!name.empty() && on_rng)) ++n;
  }
  return n;
}

/// Lines where two or more draws meet in one expression whose evaluation order C++ leaves
/// open: the arguments of one call, or the operands of one operator. Pieces are cut at `;`,
/// braces, and commas outside parentheses (declarators and braced lists are evaluated in
/// order). A conditional or `&&` between two draws is flagged too: write it in two statements.
std::vector<int> unsequencedDrawLines(const std::string& source) {
  const std::string code = blankCommentsAndLiterals(source);
  std::vector<int> lines;
  std::string piece;
  int line = 1, piece_line = 1, parens = 0;
  std::vector<int> saved;  // paren depth outside each open brace
  auto cut = [&] {
    if (countDraws(piece) >= 2 && (lines.empty() || lines.back() != piece_line)) lines.push_back(piece_line);
    piece.clear();
    piece_line = line;
  };
  for (const char c : code) {
    if (c == ';' || c == '{' || c == '}' || (c == ',' && parens == 0)) {
      cut();
      if (c == '{') { saved.push_back(parens); parens = 0; }
      if (c == '}' && !saved.empty()) { parens = saved.back(); saved.pop_back(); }
    } else {
      if (c == '(' || c == '[') ++parens;
      if ((c == ')' || c == ']') && parens > 0) --parens;
      if (piece.empty() && (c == ' ' || c == '\n')) {
        if (c == '\n') ++line;
        piece_line = line;
        continue;
      }
      piece += c == '\n' ? ' ' : c;
    }
    if (c == '\n') ++line;
  }
  cut();
  return lines;
}

TEST(Random, TheTreeCheckFlagsUnsequencedDrawsOnly) {
  const std::vector<std::string> flagged = {
      "p.emplace_back(rng.uniform(), rng.uniform(), 0.f);",
      "Eigen::Vector3f v(rng.gaussian(),\n  rng.gaussian(), rng.gaussian());",
      "x = o + rng.uniform(-1, 1) * u + rng.uniform(-1, 1) * v;",
      "q.push_back(Eigen::Vector3f(u(rng), u(rng), 0.f));",
      "cloud(8 + int(random->below(24)), 8 + int(random->below(24)));",
      "const float a = float(rng.uniform(1, 3) * (rng.below(2) ? 1 : -1));",
  };
  for (const auto& s : flagged) EXPECT_EQ(unsequencedDrawLines(s).size(), 1u) << s;
  const std::vector<std::string> clean = {
      "const double z = rng.gaussian(), y = rng.gaussian();",
      "v.push_back({rng.below(4), rng.below(4)});",
      "for (int i = 0; i < n; ++i) { const double y = rng.uniform(); p.emplace_back(rng.uniform(), y, 0.f); }",
      "// p.emplace_back(rng.uniform(), rng.uniform());",
      "/* Vector3d(rng.gaussian(), rng.gaussian()) */ x = rng.gaussian3();",
      "log(\"rng.uniform(), rng.uniform()\", rng.uniform());",
      "p.emplace_back(std::uniform(a), b.uniform(2));",  // one member draw only
  };
  for (const auto& s : clean) EXPECT_TRUE(unsequencedDrawLines(s).empty()) << s;
  EXPECT_EQ(unsequencedDrawLines("a();\nb();\np.emplace_back(rng.uniform(),\n rng.uniform());"), std::vector<int>{3});
}

std::string fileText(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

TEST(Random, NoUnsequencedDrawsInTheTree) {
  // docs/examples draw from std distributions, whose values differ between standard
  // libraries anyway, and are left as a user would write them.
  namespace fs = std::filesystem;
  std::size_t files = 0;
  std::ostringstream found;
  for (const char* dir : {"modules", "apps", "test"}) {
    for (const auto& entry : fs::recursive_directory_iterator(fs::path(PAPS_SOURCE_DIR) / dir)) {
      const std::string ext = entry.path().extension().string();
      if (!entry.is_regular_file() || (ext != ".cpp" && ext != ".hpp" && ext != ".h")) continue;
      const std::string relative = fs::relative(entry.path(), PAPS_SOURCE_DIR).generic_string();
      if (relative == "test/core/random.cpp") continue;  // this file's own examples
      ++files;
      for (int l : unsequencedDrawLines(fileText(entry.path())))
        found << relative << ":" << l << "\n";
    }
  }
  EXPECT_GT(files, 100u);
  EXPECT_EQ(found.str(), "") << "draw into named variables, one statement each (paps/core/random.h)";
}

// The unity build of the tests (PAPS_UNITY_TESTS) compiles a module's test files a few at a
// time as one unit: each file keeps its helpers in a namespace of its own,
// <module>_<file>_test, never in an anonymous one, where a helper of another file in the
// batch would clash with its own or be called in its place.
TEST(SourceTree, EveryTestFileNamesItsOwnNamespace) {
  namespace fs = std::filesystem;
  std::size_t files = 0;
  std::ostringstream found;
  for (const std::string module : {"core", "filters", "features", "surface", "compression", "fusion"}) {
    for (const auto& entry : fs::directory_iterator(fs::path(PAPS_SOURCE_DIR) / "test" / module)) {
      const std::string stem = entry.path().stem().string();
      if (!entry.is_regular_file() || entry.path().extension() != ".cpp" || stem.rfind("fuzz_", 0) == 0) continue;
      const std::string code = blankCommentsAndLiterals(fileText(entry.path()));
      ++files;
      const std::string where = "test/" + module + "/" + stem + ".cpp";
      if (code.find("namespace " + module + "_" + stem + "_test {") == std::string::npos)
        found << where << ": no namespace " << module << "_" << stem << "_test\n";
      for (std::size_t at = code.find("namespace"); at != std::string::npos; at = code.find("namespace", at + 1)) {
        std::size_t k = at + 9;
        while (k < code.size() && std::isspace(static_cast<unsigned char>(code[k]))) ++k;
        if (k < code.size() && code[k] == '{') found << where << ": an anonymous namespace\n";
      }
    }
  }
  EXPECT_GT(files, 40u);
  EXPECT_EQ(found.str(), "");
}

}  // namespace core_random_test
