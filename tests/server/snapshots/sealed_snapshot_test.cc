// The seal of a session snapshot: what it accepts and everything it refuses (altered,
// truncated, another key, no key, another version, too large), and the state directory's
// file rules.
#include "server/snapshots/sealed_snapshot.h"

#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "absl/strings/str_cat.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "server/snapshots/owner_only_file.h"
#include "server/snapshots/snapshot_store.h"

namespace nupmpc::server {
namespace {

using ::testing::HasSubstr;

constexpr std::size_t kMax = 1 << 20;

snapshot::v1::SessionSnapshot Example() {
  snapshot::v1::SessionSnapshot s;
  s.set_format_version(kSnapshotFormatVersion);
  s.set_session_id("0123456789abcdef0123456789abcdef");
  s.set_owner_principal("alice");
  s.set_core_state(std::string(100, '\x07'));
  s.set_written_unix_ms(1);
  return s;
}

Caller Principal(const std::string& name) {
  Caller caller;
  caller.principal = name;
  return caller;
}

SnapshotKey Key(char fill) { return *SnapshotKey::FromBytes(std::string(32, fill)); }

TEST(SealedSnapshotTest, RoundTripsWithAndWithoutAKey) {
  for (const SnapshotKey& key : {SnapshotKey(), Key('k')}) {
    absl::StatusOr<snapshot::v1::SessionSnapshot> back = Unseal(Seal(Example(), key), key, kMax);
    ASSERT_TRUE(back.ok()) << back.status();
    EXPECT_EQ(back->SerializeAsString(), Example().SerializeAsString());
  }
}

TEST(SealedSnapshotTest, NoFlippedByteOrTruncationGivesAnotherSnapshot) {
  for (const SnapshotKey& key : {SnapshotKey(), Key('k')}) {
    const std::string sealed = Seal(Example(), key);
    int refused = 0;
    for (std::size_t i = 0; i < sealed.size(); ++i) {
      std::string altered = sealed;
      altered[i] = static_cast<char>(altered[i] ^ 0x20);
      // Refused, or (a flip the framing absorbs, e.g. the flag true written as 33) the same snapshot.
      const absl::StatusOr<snapshot::v1::SessionSnapshot> unsealed = Unseal(altered, key, kMax);
      if (unsealed.ok()) {
        EXPECT_EQ(unsealed->SerializeAsString(), Example().SerializeAsString()) << "byte " << i;
      }
      refused += unsealed.ok() ? 0 : 1;
      EXPECT_FALSE(Unseal(absl::string_view(sealed).substr(0, i), key, kMax).ok()) << "first " << i << " bytes";
    }
    EXPECT_GE(refused, static_cast<int>(sealed.size()) - 2);
  }
}

TEST(SealedSnapshotTest, AnotherKeyNoKeyAnotherVersionAndOversizeAreRefusedWithTheReason) {
  const std::string keyed = Seal(Example(), Key('k'));
  EXPECT_THAT(std::string(Unseal(keyed, Key('x'), kMax).status().message()), HasSubstr("integrity tag"));
  EXPECT_THAT(std::string(Unseal(keyed, SnapshotKey(), kMax).status().message()), HasSubstr("sealed with a key"));
  EXPECT_THAT(std::string(Unseal(Seal(Example(), SnapshotKey()), Key('k'), kMax).status().message()),
              HasSubstr("requires one"));
  snapshot::v1::SessionSnapshot future = Example();
  future.set_format_version(kSnapshotFormatVersion + 1);
  EXPECT_THAT(std::string(Unseal(Seal(future, Key('k')), Key('k'), kMax).status().message()),
              HasSubstr("format version"));
  EXPECT_THAT(std::string(Unseal(keyed, Key('k'), keyed.size() - 1).status().message()), HasSubstr("more than"));
  EXPECT_FALSE(SnapshotKey::FromBytes(std::string(kMinSnapshotKeyBytes - 1, 'k')).ok());
}

class StateDirTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::path(::testing::TempDir()) / absl::StrCat("state_dir_test.", getpid());
    std::filesystem::remove_all(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string File(const std::string& name) const { return (dir_ / name).string(); }
  // The store on this directory, unkeyed, with a 60 s re-attach window.
  absl::StatusOr<std::unique_ptr<SnapshotStore>> OpenStore() const {
    SnapshotStoreOptions options;
    options.dir = dir_.string();
    options.max_snapshot_bytes = kMax;
    options.reattach_window_s = 60;
    return SnapshotStore::Open(options);
  }
  std::filesystem::path dir_;
};

TEST_F(StateDirTest, BadFilesAreSkippedAndLeftAndGoodOnesClaimedOnceByTheirOwnerOnly) {
  ASSERT_TRUE(PrepareOwnerOnlyDirectory(dir_.string(), "test").ok());
  snapshot::v1::SessionSnapshot good = Example();
  good.set_written_unix_ms(UnixMillisecondsNow());
  const std::string id = good.session_id();
  ASSERT_TRUE(WriteOwnerOnlyFileAtomically(File(id + ".snapshot"), Seal(good, SnapshotKey())).ok());
  // Corrupt, truncated, a foreign version, readable by others, one named after another id,
  // and one larger than a snapshot may be.
  const std::string sealed = Seal(good, SnapshotKey());
  const std::string corrupt_id(32, 'c'), truncated_id(32, 'd'), foreign_id(32, 'e'), open_id(32, 'f'),
      renamed_id(32, 'a');
  ASSERT_TRUE(WriteOwnerOnlyFileAtomically(File(corrupt_id + ".snapshot"), "not a snapshot").ok());
  ASSERT_TRUE(WriteOwnerOnlyFileAtomically(File(truncated_id + ".snapshot"), sealed.substr(0, sealed.size() / 2)).ok());
  snapshot::v1::SessionSnapshot foreign = good;
  foreign.set_session_id(foreign_id);
  foreign.set_format_version(kSnapshotFormatVersion + 1);
  ASSERT_TRUE(WriteOwnerOnlyFileAtomically(File(foreign_id + ".snapshot"), Seal(foreign, SnapshotKey())).ok());
  ASSERT_TRUE(WriteOwnerOnlyFileAtomically(File(open_id + ".snapshot"), sealed).ok());
  ASSERT_EQ(chmod(File(open_id + ".snapshot").c_str(), 0644), 0);
  ASSERT_TRUE(WriteOwnerOnlyFileAtomically(File(renamed_id + ".snapshot"), sealed).ok());
  const std::string oversized_id(32, '9');
  ASSERT_TRUE(WriteOwnerOnlyFileAtomically(File(oversized_id + ".snapshot"), std::string(kMax + 1, 'x')).ok());

  absl::StatusOr<std::unique_ptr<SnapshotStore>> store = OpenStore();
  ASSERT_TRUE(store.ok()) << store.status();
  EXPECT_EQ((*store)->found_at_start(), 1u);
  EXPECT_EQ((*store)->refused(), 6u);
  // Skipped, never restored, and left for whoever can read them (another replica's key or
  // version) or for the operator.
  for (const std::string& bad : {corrupt_id, truncated_id, foreign_id, open_id, renamed_id, oversized_id}) {
    EXPECT_TRUE(std::filesystem::exists(File(bad + ".snapshot"))) << bad;
    EXPECT_TRUE(absl::IsNotFound((*store)->Claim(bad, Principal("alice")).status())) << bad;
  }
  // Another principal gets NOT_FOUND and the file stays; its owner gets it, once.
  EXPECT_TRUE(absl::IsNotFound((*store)->Claim(id, Principal("bob")).status()));
  EXPECT_TRUE(std::filesystem::exists(File(id + ".snapshot")));
  absl::StatusOr<snapshot::v1::SessionSnapshot> claimed = (*store)->Claim(id, Principal("alice"));
  ASSERT_TRUE(claimed.ok()) << claimed.status();
  EXPECT_EQ(claimed->core_state(), good.core_state());
  EXPECT_FALSE(std::filesystem::exists(File(id + ".snapshot")));
  EXPECT_TRUE(absl::IsNotFound((*store)->Claim(id, Principal("alice")).status()));
}

TEST_F(StateDirTest, AStreamOwnedSessionIsClaimedOnlyByAControlStream) {
  ASSERT_TRUE(PrepareOwnerOnlyDirectory(dir_.string(), "test").ok());
  snapshot::v1::SessionSnapshot owned = Example();
  owned.set_owned_by_stream(true);
  owned.set_written_unix_ms(UnixMillisecondsNow());
  ASSERT_TRUE(WriteOwnerOnlyFileAtomically(File(owned.session_id() + ".snapshot"), Seal(owned, SnapshotKey())).ok());
  absl::StatusOr<std::unique_ptr<SnapshotStore>> store = OpenStore();
  ASSERT_TRUE(store.ok());
  EXPECT_TRUE(
      absl::IsNotFound((*store)->Claim(owned.session_id(), Principal("alice"), /*by_control_stream=*/false).status()));
  EXPECT_TRUE(std::filesystem::exists(File(owned.session_id() + ".snapshot")));
  EXPECT_TRUE((*store)->Claim(owned.session_id(), Principal("alice"), /*by_control_stream=*/true).ok());
}

TEST_F(StateDirTest, ASnapshotOlderThanTheWindowIsRemovedNotRestored) {
  ASSERT_TRUE(PrepareOwnerOnlyDirectory(dir_.string(), "test").ok());
  snapshot::v1::SessionSnapshot old = Example();  // written at 1 ms after the epoch
  ASSERT_TRUE(WriteOwnerOnlyFileAtomically(File(old.session_id() + ".snapshot"), Seal(old, SnapshotKey())).ok());
  absl::StatusOr<std::unique_ptr<SnapshotStore>> store = OpenStore();
  ASSERT_TRUE(store.ok());
  EXPECT_EQ((*store)->found_at_start(), 0u);
  EXPECT_FALSE(std::filesystem::exists(File(old.session_id() + ".snapshot")));
}

TEST_F(StateDirTest, ADirectoryOthersCanWriteIsRefused) {
  std::filesystem::create_directories(dir_);
  ASSERT_EQ(chmod(dir_.c_str(), 0777), 0);
  SnapshotStoreOptions options;
  options.dir = dir_.string();
  EXPECT_THAT(std::string(SnapshotStore::Open(options).status().message()), HasSubstr("not writable by group"));
}

}  // namespace
}  // namespace nupmpc::server
