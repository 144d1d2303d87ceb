// Bearer-token authentication of cloudbake-server (--auth-tokens FILE): who is calling, so each
// client sees and acts only on its own jobs. The standard health service stays open for probes.
#pragma once

#include <grpcpp/grpcpp.h>

#include <map>
#include <string>

namespace cloudbake::server {

/// Tokens and the client names they stand for, read from a file of lines `NAME TOKEN` ('#'
/// starts a comment). Throws std::runtime_error naming the file and line for a malformed line,
/// a short token (under 16 characters) or a repeated name or token.
class TokenTable {
 public:
  static TokenTable load(const std::string& path);
  size_t size() const { return names_.size(); }
  /// The client a token belongs to, or "" for an unknown token (compared in constant time).
  std::string nameOf(const std::string& token) const;

 private:
  std::map<std::string, std::string> names_;  // token -> name
};

/// Authenticates calls: with no table every call is anonymous (caller ""); with one, a call
/// must carry `authorization: Bearer TOKEN` metadata of a listed token.
class Authenticator {
 public:
  Authenticator() = default;
  explicit Authenticator(TokenTable tokens) : tokens_(std::move(tokens)), enabled_(true) {}
  bool enabled() const { return enabled_; }
  /// OK with *caller set, or UNAUTHENTICATED naming what is missing.
  grpc::Status authenticate(const grpc::ServerContext& ctx, std::string* caller) const;

 private:
  TokenTable tokens_;
  bool enabled_ = false;
};

}  // namespace cloudbake::server
