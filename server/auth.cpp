#include "server/auth.h"

#include <fstream>
#include <set>
#include <sstream>
#include <stdexcept>

namespace cloudbake::server {
namespace {

constexpr size_t kMinTokenLength = 16;

bool validName(const std::string& name) {
  if (name.empty() || name.size() > 64) return false;
  for (const char c : name) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
                    c == '.' || c == '_' || c == '-' || c == '@';
    if (!ok) return false;
  }
  return true;
}

// Every byte of the longer string is looked at whatever matches, so the time taken says nothing
// about how much of a guessed token was right.
bool equalConstantTime(const std::string& a, const std::string& b) {
  const size_t n = std::max(a.size(), b.size());
  unsigned diff = unsigned(a.size() ^ b.size());
  for (size_t i = 0; i < n; ++i) {
    const unsigned char x = i < a.size() ? static_cast<unsigned char>(a[i]) : 0;
    const unsigned char y = i < b.size() ? static_cast<unsigned char>(b[i]) : 0;
    diff |= unsigned(x ^ y);
  }
  return diff == 0;
}

// Where a line's comment starts: a '#' at its start or after a blank. A '#' inside a token is
// part of it (cutting there had accepted the token's first characters alone as the secret).
size_t commentStart(const std::string& line) {
  for (size_t i = 0; i < line.size(); ++i) {
    if (line[i] == '#' && (i == 0 || line[i - 1] == ' ' || line[i - 1] == '\t')) return i;
  }
  return line.size();
}

}  // namespace

TokenTable TokenTable::load(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error("--auth-tokens " + path + ": cannot open");
  TokenTable table;
  std::set<std::string> names;
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    const std::string where = "--auth-tokens " + path + ":" + std::to_string(number) + ": ";
    std::istringstream words(line.substr(0, commentStart(line)));
    std::string name, token, extra;
    if (!(words >> name)) continue;  // blank or comment
    if (!(words >> token) || (words >> extra)) {
      throw std::runtime_error(where + "expected 'NAME TOKEN'");
    }
    if (!validName(name)) {
      throw std::runtime_error(where + "name must be 1-64 of [A-Za-z0-9._@-]");
    }
    if (token.size() < kMinTokenLength) {
      throw std::runtime_error(where + "token must be at least 16 characters");
    }
    if (!names.insert(name).second || table.names_.count(token)) {
      throw std::runtime_error(where + "name or token repeated");
    }
    table.names_[token] = name;
  }
  if (in.bad()) throw std::runtime_error("--auth-tokens " + path + ": read error");
  if (table.names_.empty()) throw std::runtime_error("--auth-tokens " + path + ": no tokens");
  return table;
}

std::string TokenTable::nameOf(const std::string& token) const {
  std::string found;
  for (const auto& [known, name] : names_) {
    if (equalConstantTime(known, token)) found = name;
  }
  return found;
}

grpc::Status Authenticator::authenticate(const grpc::ServerContext& ctx,
                                         std::string* caller) const {
  caller->clear();
  if (!enabled_) return grpc::Status::OK;
  const auto& metadata = ctx.client_metadata();
  const auto it = metadata.find("authorization");
  if (it == metadata.end()) {
    return {grpc::StatusCode::UNAUTHENTICATED,
            "this server requires a token: send 'authorization: Bearer TOKEN' (cloudctl: "
            "CLOUDBAKE_TOKEN or --token-file)"};
  }
  const std::string value(it->second.data(), it->second.size());
  const std::string prefix = "Bearer ";
  *caller = value.rfind(prefix, 0) == 0 ? tokens_.nameOf(value.substr(prefix.size())) : "";
  if (caller->empty()) return {grpc::StatusCode::UNAUTHENTICATED, "unknown token"};
  return grpc::Status::OK;
}

}  // namespace cloudbake::server
