// TLS and bearer tokens (server/auth): certificates made at test time with openssl; with tokens a
// client sees and acts only on its own jobs, an unknown or missing token is refused, and the
// standard health service stays open for probes.
#include <nlohmann/json.hpp>

#include "tests/server/server_fixture.h"

namespace cloudbake::testing {
namespace {

using Json = nlohmann::json;

/// A CA and a server certificate for 127.0.0.1 and localhost, signed by it; false without openssl.
bool makeCertificates(const Workspace& ws) {
  const std::string d = ws.path("");
  const std::string cmd =
      "(cd " + d +
      " && openssl req -x509 -newkey rsa:2048 -nodes -keyout ca.key -out ca.pem -days 2 "
      "-subj /CN=cloudbake-test-ca"
      " && openssl req -newkey rsa:2048 -nodes -keyout server.key -out server.csr "
      "-subj /CN=localhost"
      " && printf 'subjectAltName=IP:127.0.0.1,DNS:localhost\\n' > san.ext"
      " && openssl x509 -req -in server.csr -CA ca.pem -CAkey ca.key -CAcreateserial "
      "-out server.pem -days 2 -extfile san.ext) >/dev/null 2>&1";
  return run(cmd).code == 0;
}

class SecurityTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!makeCertificates(ws_)) GTEST_SKIP() << "openssl could not make test certificates";
    ws_.write(
        "tokens.txt",
        "# name token\nalice alice-token-0123456789\nbob   bob-token-0123456789abc#x  # bob's\n");
    server_.clientFlags(" --tls-ca " + ws_.path("ca.pem"));
    ASSERT_TRUE(server_.start({"--tls-cert=" + ws_.path("server.pem"),
                               "--tls-key=" + ws_.path("server.key"),
                               "--auth-tokens=" + ws_.path("tokens.txt")}));
  }
  void TearDown() override { server_.stop(); }
  std::string as(const std::string& token) const {
    return "CLOUDBAKE_TOKEN=" + token + " " + server_.cloudctl(30);
  }
  Workspace ws_;
  ServerProc server_{ws_.path("state")};
};

TEST_F(SecurityTest, TlsAndTokensKeepEachClientToItsOwnJobs) {
  // Health is open to probes; plaintext to a TLS server fails.
  EXPECT_EQ(run(server_.cloudctl() + " health").code, 0);
  const std::string plain =
      std::string(CLOUDCTL_BIN) + " --server " + server_.address() + " --timeout 2 health";
  EXPECT_EQ(run(plain).code, 4);

  // No token, or an unknown one: refused as the caller's own mistake (exit 2).
  CmdResult r = run(server_.cloudctl() + " list");
  EXPECT_EQ(r.code, 2) << r.err;
  EXPECT_NE(r.err.find("requires a token"), std::string::npos) << r.err;
  r = run(as("wrong-token-0123456789") + " list");
  EXPECT_EQ(r.code, 2) << r.err;
  EXPECT_NE(r.err.find("unknown token"), std::string::npos) << r.err;

  const std::string shot = ws_.write("s.json", sphereShot(16, 4));
  r = run(as("alice-token-0123456789") + " --json submit " + shot + " --quiet --out " +
          ws_.path("a"));
  ASSERT_EQ(r.code, 0) << r.err;
  const std::string id = Json::parse(r.out).at("id");

  // Bob sees none of it: his list is empty and every call on Alice's job is "not found".
  // A '#' inside a token is part of it: its first characters alone are not the secret (the
  // file's reader had cut the token there, and accepted them).
  r = run(as("bob-token-0123456789abc") + " list");
  EXPECT_EQ(r.code, 2) << r.err;
  EXPECT_NE(r.err.find("unknown token"), std::string::npos) << r.err;
  const std::string bob = as("'bob-token-0123456789abc#x'");
  r = run(bob + " --json list");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(Json::parse(r.out).empty()) << r.out;
  for (const std::string& call :
       {"status " + id, "cancel " + id, "fetch " + id + " --out " + ws_.path("b"),
        "render " + id + " --out " + ws_.path("b2"), "watch " + id}) {
    r = run(bob + " " + call);
    EXPECT_EQ(r.code, 3) << call << ": " << r.err;
    EXPECT_NE(r.err.find("not found"), std::string::npos) << call << ": " << r.err;
  }
  EXPECT_FALSE(std::filesystem::exists(ws_.path("b")));

  // Alice, with her token in a file this time, sees and fetches her job.
  ws_.write("alice.token", "alice-token-0123456789\n");
  const std::string alice = server_.cloudctl(30) + " --token-file " + ws_.path("alice.token");
  r = run(alice + " --json list");
  ASSERT_EQ(r.code, 0) << r.err;
  ASSERT_EQ(Json::parse(r.out).size(), 1u);
  EXPECT_EQ(Json::parse(r.out)[0].at("id"), id);
  EXPECT_EQ(run(alice + " fetch " + id + " --out " + ws_.path("a2")).code, 0);
  EXPECT_GT(std::filesystem::file_size(ws_.path("a2/front.exr")), 0u);
}

TEST(SecurityFlags, BadTlsAndTokenSettingsStopTheServerWithTheReason) {
  Workspace ws;
  ws.write("short.txt", "alice short\n");
  ws.write("cert.pem", "not a certificate");
  struct Case {
    std::vector<std::string> flags;
    std::string message;
  };
  const Case cases[] = {
      {{"--tls-cert=" + ws.path("cert.pem")}, "--tls-cert and --tls-key go together"},
      {{"--auth-tokens=" + ws.path("short.txt")}, "short.txt:1: token must be at least 16"},
  };
  for (const Case& c : cases) {
    ServerProc server(ws.path("state"));
    server.logTo(ws.path("server.log"));
    EXPECT_FALSE(server.start(c.flags));
    EXPECT_NE(slurp(ws.path("server.log")).find(c.message), std::string::npos)
        << slurp(ws.path("server.log"));
  }
}

}  // namespace
}  // namespace cloudbake::testing
