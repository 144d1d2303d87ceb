// What the command-line tools say about a mistyped subcommand: its name and the nearest
// command, instead of CLI11's "A subcommand is required". Header-only, beside exit_codes.h.
#pragma once

#include <algorithm>
#include <cstring>
#include <string>
#include <vector>

namespace cloudbake {

/// Optimal string alignment distance (edits, with a swap of neighbours counting one):
/// "sumbit" is 1 from "submit".
inline size_t editDistance(const std::string& a, const std::string& b) {
  std::vector<std::vector<size_t>> d(a.size() + 1, std::vector<size_t>(b.size() + 1));
  for (size_t i = 0; i <= a.size(); ++i) d[i][0] = i;
  for (size_t j = 0; j <= b.size(); ++j) d[0][j] = j;
  for (size_t i = 1; i <= a.size(); ++i) {
    for (size_t j = 1; j <= b.size(); ++j) {
      const size_t cost = a[i - 1] == b[j - 1] ? 0 : 1;
      d[i][j] = std::min({d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + cost});
      if (i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1]) {
        d[i][j] = std::min(d[i][j], d[i - 2][j - 2] + 1);
      }
    }
  }
  return d[a.size()][b.size()];
}

/// The command nearest to `word` within max(2, |word| / 3) edits ("" when none is that near).
inline std::string nearestCommand(const std::string& word,
                                  const std::vector<std::string>& commands) {
  std::string best;
  size_t best_d = std::max<size_t>(2, word.size() / 3) + 1;
  for (const std::string& c : commands) {
    const size_t d = editDistance(word, c);
    if (d < best_d) best_d = d, best = c;
  }
  return best;
}

/// The first argument that is neither an option, nor the value of one of `value_options`
/// (given as "--name"; "--name=value" needs no skipping), nor one of `commands`: a mistyped
/// command ("" when there is none).
inline std::string unknownCommand(int argc, const char* const* argv,
                                  const std::vector<std::string>& commands,
                                  const std::vector<std::string>& value_options) {
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a.rfind("-", 0) == 0) {
      if (std::find(value_options.begin(), value_options.end(), a) != value_options.end()) ++i;
      continue;
    }
    if (std::find(commands.begin(), commands.end(), a) != commands.end()) return "";
    return a;
  }
  return "";
}

/// "unknown command 'sumbit' (did you mean 'submit'?); commands: a, b, c".
inline std::string unknownCommandMessage(const std::string& word,
                                         const std::vector<std::string>& commands) {
  std::string m = "unknown command '" + word + "'";
  const std::string near = nearestCommand(word, commands);
  if (!near.empty()) m += " (did you mean '" + near + "'?)";
  m += "; commands:";
  for (size_t i = 0; i < commands.size(); ++i) m += (i ? ", " : " ") + commands[i];
  return m;
}

}  // namespace cloudbake
