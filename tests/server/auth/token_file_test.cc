// The tokens file's format and its comparison in constant time.
#include "server/auth/token_file.h"

#include <filesystem>
#include <fstream>

#include "gtest/gtest.h"

namespace nupmpc::server {
namespace {

TEST(TokenFile, ParsesGrantsCommentsAndTheAdminRole) {
  auto grants = ParseTokenFile(
      "# operators\n"
      "0123456789abcdef0123 alice\n"
      "\n"
      "  fedcba9876543210fedc\tops admin   # the on-call\n",
      "tokens");
  ASSERT_TRUE(grants.ok()) << grants.status();
  ASSERT_EQ(grants->size(), 2u);
  EXPECT_EQ((*grants)[0].principal.name, "alice");
  EXPECT_FALSE((*grants)[0].principal.admin);
  EXPECT_EQ((*grants)[1].token, "fedcba9876543210fedc");
  EXPECT_EQ((*grants)[1].principal.name, "ops");
  EXPECT_TRUE((*grants)[1].principal.admin);
}

TEST(TokenFile, ErrorsNameTheLineAndNeverTheToken) {
  const char* secret = "0123456789abcdef0123";
  for (const std::string& text : {std::string("# header\n") + secret + "\n",          // no principal
                                  std::string("\n\n") + secret + " alice root\n",     // unknown role
                                  std::string("\n") + "short alice\n",                // guessable
                                  std::string(secret) + " a\n" + secret + " b\n"}) {  // repeated
    auto grants = ParseTokenFile(text, "tokens.txt");
    ASSERT_FALSE(grants.ok()) << text;
    EXPECT_EQ(grants.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_NE(grants.status().message().find("tokens.txt:"), std::string::npos) << grants.status();
    EXPECT_EQ(grants.status().message().find(secret), std::string::npos) << grants.status();
  }
  EXPECT_NE(ParseTokenFile("\n\nx y z w\n", "f").status().message().find("f:3:"), std::string::npos);
}

TEST(TokenFile, ConstantTimeEqualityIsEquality) {
  EXPECT_TRUE(ConstantTimeEquals("abcdef", "abcdef"));
  EXPECT_TRUE(ConstantTimeEquals("", ""));
  EXPECT_FALSE(ConstantTimeEquals("abcdef", "abcdeg"));
  EXPECT_FALSE(ConstantTimeEquals("abcdef", "abcde"));
  EXPECT_FALSE(ConstantTimeEquals("abc", "abcdef"));
  EXPECT_FALSE(ConstantTimeEquals(std::string("ab\0", 3), "ab"));
}

TEST(TokenStore, AChangedFileIsReReadAndABrokenOneKeepsTheTokensBefore) {
  const std::string path = ::testing::TempDir() + "/tokens-" + std::to_string(::getpid());
  const auto write = [&](const std::string& text) {
    const std::string staged = path + ".new";
    std::ofstream(staged) << text;
    std::filesystem::rename(staged, path);  // a new inode: seen even within one mtime tick
  };
  write("aaaaaaaaaaaaaaaaaaaa alice\n");
  auto store = TokenStore::Open(path);
  ASSERT_TRUE(store.ok()) << store.status();
  EXPECT_EQ((*store)->Authenticate("aaaaaaaaaaaaaaaaaaaa")->name, "alice");
  EXPECT_FALSE((*store)->Authenticate("bbbbbbbbbbbbbbbbbbbb").has_value());
  EXPECT_FALSE(*(*store)->ReloadIfChanged());  // unchanged

  write("bbbbbbbbbbbbbbbbbbbb bob admin\n");
  EXPECT_TRUE(*(*store)->ReloadIfChanged());
  EXPECT_FALSE((*store)->Authenticate("aaaaaaaaaaaaaaaaaaaa").has_value());
  EXPECT_TRUE((*store)->Authenticate("bbbbbbbbbbbbbbbbbbbb")->admin);

  write("bbbbbbbbbbbbbbbbbbbb\n");  // malformed
  EXPECT_FALSE((*store)->ReloadIfChanged().ok());
  EXPECT_TRUE((*store)->Authenticate("bbbbbbbbbbbbbbbbbbbb").has_value());

  std::filesystem::remove(path);  // reported once; the tokens stay
  EXPECT_FALSE((*store)->ReloadIfChanged().ok());
  EXPECT_FALSE(*(*store)->ReloadIfChanged());
  EXPECT_TRUE((*store)->Authenticate("bbbbbbbbbbbbbbbbbbbb").has_value());
  write("cccccccccccccccccccc carol\n");  // and a file that comes back is read again
  EXPECT_TRUE(*(*store)->ReloadIfChanged());
  EXPECT_EQ((*store)->Authenticate("cccccccccccccccccccc")->name, "carol");

  EXPECT_FALSE(TokenStore::Open(path + ".missing").ok());
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace nupmpc::server
