// Nothing lost: `tuile render` run as a real child process and stopped with real signals.
// SIGINT / SIGTERM leave a valid EXR of the complete passes (its header's spp is what it
// holds: the bits of an uninterrupted render of that many samples) and exit 130 / 143; a
// render killed with SIGKILL while it writes checkpoints leaves one that loads and resumes;
// --resume gives the bits of a render that never stopped; an output that cannot be written
// fails in under a second; --target-error stops within a factor of two of its target
// (against a reference); atomic writes leave the previous file when they fail.
//
// The tests wait for events (a checkpoint file appearing, a child exiting), never for a
// fixed time; where they signal a child at some moment, what they check holds whatever
// that moment is.
#include <gtest/gtest.h>

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "measure/metrics.h"
#include "render/checkpoint.h"
#include "scene/atomic_file.h"
#include "output_files.h"
#include "test_scale.h"
#include "scene/image_io.h"

extern char** environ;

using namespace tuile;
using tuile::testing::same_pixels;
using tuile::testing::TempDir;
namespace fs = std::filesystem;

namespace {

struct Child {
  pid_t pid = -1;
  std::string log;  // its stderr and stdout
};

Child spawn_tuile(const std::vector<std::string>& args, const std::string& log) {
  std::vector<std::string> all = {TUILE_BINARY};
  all.insert(all.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& a : all) argv.push_back(a.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 1, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&fa, 1, 2);
  Child c;
  c.log = log;
  const int err = posix_spawn(&c.pid, argv[0], &fa, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&fa);
  if (err != 0) c.pid = -1;
  return c;
}

std::string read_file(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// The child's exit: its code, or 1000 + the signal that killed it.
int wait_child(const Child& c) {
  int status = 0;
  if (waitpid(c.pid, &status, 0) != c.pid) return -1;
  if (WIFEXITED(status)) return WEXITSTATUS(status);
  if (WIFSIGNALED(status)) return 1000 + WTERMSIG(status);
  return -1;
}

int run_tuile(const std::vector<std::string>& args, const std::string& log) {
  const Child c = spawn_tuile(args, log);
  return c.pid > 0 ? wait_child(c) : -1;
}

// Waits until `path` exists or the child has exited (true: it exists and the child runs).
bool wait_for_file(const Child& c, const std::string& path) {
  const auto t0 = std::chrono::steady_clock::now();
  while (std::chrono::steady_clock::now() - t0 < std::chrono::seconds(120)) {
    if (fs::exists(path)) return true;
    int status = 0;
    if (waitpid(c.pid, &status, WNOHANG) == c.pid) return false;  // ended before it wrote one
    std::this_thread::yield();
  }
  return false;
}

int header_spp(const std::string& exr) {
  const ExrMetadata m = read_exr_metadata(exr);
  const int* spp = m.find_integer("spp");
  return spp ? *spp : -1;
}

const std::vector<std::string> kScene = {"render", "built-in:cornell", "--res", "96x64", "--threads", "2"};

std::vector<std::string> with(std::vector<std::string> a, const std::vector<std::string>& more) {
  a.insert(a.end(), more.begin(), more.end());
  return a;
}

// A render that runs long, stopped by `sig` once its first checkpoint exists: the image
// holds complete passes only, exactly the uninterrupted render of that many samples.
void interrupt_and_check(int sig, int expected_exit) {
  TempDir dir;
  const std::string out = dir / "long.exr";
  const Child c = spawn_tuile(with(kScene, {"--spp", "1000000", "--checkpoint", "0.001", "-o", out}), dir / "log");
  ASSERT_GT(c.pid, 0);
  ASSERT_TRUE(wait_for_file(c, checkpoint_path(out))) << read_file(c.log);
  ASSERT_EQ(kill(c.pid, sig), 0);
  ASSERT_EQ(wait_child(c), expected_exit) << read_file(c.log);
  const ExrMetadata m = read_exr_metadata(out);
  const int spp = header_spp(out);
  ASSERT_GT(spp, 0);
  ASSERT_NE(m.find_text("stoppedBy"), nullptr);
  EXPECT_EQ(*m.find_text("stoppedBy"), "interrupted");
  ASSERT_NE(m.find_text("commandLine"), nullptr);
  EXPECT_NE(m.find_text("commandLine")->find("--spp 1000000"), std::string::npos) << *m.find_text("commandLine");
  // the checkpoint saved on the way out holds the same samples
  EXPECT_EQ(load_checkpoint(checkpoint_path(out)).film.samples, static_cast<uint64_t>(spp));
  // the content is the uninterrupted render of the header's spp, bit for bit
  const std::string ref = dir / "ref.exr";
  ASSERT_EQ(run_tuile(with(kScene, {"--spp", std::to_string(spp), "-o", ref, "--quiet"}), dir / "log2"), 0);
  EXPECT_TRUE(same_pixels(out, ref)) << spp << " spp";
  EXPECT_EQ(header_spp(ref), spp);
}

}  // namespace

TEST(NothingLost, SigintWritesCompletePassesAndExits130) { interrupt_and_check(SIGINT, 130); }

TEST(NothingLost, SigtermWritesCompletePassesAndExits143) { interrupt_and_check(SIGTERM, 143); }

// A render stopped before its first pass is complete writes nothing: an earlier render's
// image and checkpoint of the same name stay as they were (they were replaced by an image of
// 0 spp, all black, and an empty checkpoint). Whatever moment the signal lands at, no image
// of 0 spp is ever left.
TEST(NothingLost, AStopBeforeTheFirstPassKeepsTheEarlierFiles) {
  TempDir dir;
  const std::string out = dir / "s.exr";
  const std::vector<std::string> scene = {"render", "built-in:cornell", "--threads", "2", "-o", out};
  // the earlier render: interrupted, so that it leaves a checkpoint
  const Child first = spawn_tuile(with(scene, {"--res", "96x64", "--spp", "1000000", "--checkpoint", "0.001"}), dir / "log0");
  ASSERT_GT(first.pid, 0);
  ASSERT_TRUE(wait_for_file(first, checkpoint_path(out))) << read_file(first.log);
  kill(first.pid, SIGINT);
  ASSERT_EQ(wait_child(first), 130) << read_file(first.log);
  const std::string image0 = read_file(out), checkpoint0 = read_file(checkpoint_path(out));
  ASSERT_GT(header_spp(out), 0);
  // the same name again without --resume, at a size whose first pass takes seconds (2^23
  // samples): it warns that the checkpoint exists, and is stopped as soon as it says so
  const Child second = spawn_tuile(with(scene, {"--res", "2048x2048", "--spp", "64"}), dir / "log1");
  ASSERT_GT(second.pid, 0);
  const auto t0 = std::chrono::steady_clock::now();
  while (read_file(second.log).find("an earlier render's checkpoint") == std::string::npos &&
         std::chrono::steady_clock::now() - t0 < std::chrono::seconds(120))
    std::this_thread::yield();
  ASSERT_NE(read_file(second.log).find("an earlier render's checkpoint"), std::string::npos) << read_file(second.log);
  kill(second.pid, SIGINT);
  EXPECT_EQ(wait_child(second), 130) << read_file(second.log);
  EXPECT_GT(header_spp(out), 0) << read_file(second.log);
  if (read_file(second.log).find("nothing written") != std::string::npos) {
    EXPECT_TRUE(read_file(out) == image0) << "the earlier image was replaced";
    EXPECT_TRUE(read_file(checkpoint_path(out)) == checkpoint0) << "the earlier checkpoint was replaced";
  } else {  // (the first pass won the race: its image replaced the earlier one)
    EXPECT_NE(read_file(second.log).find("complete spp"), std::string::npos) << read_file(second.log);
  }
}

TEST(NothingLost, SecondSigintAbortsWith130) {
  TempDir dir;
  const std::string out = dir / "long.exr";
  const Child c = spawn_tuile(with(kScene, {"--spp", "1000000", "--checkpoint", "0.001", "-o", out}), dir / "log");
  ASSERT_GT(c.pid, 0);
  ASSERT_TRUE(wait_for_file(c, checkpoint_path(out))) << read_file(c.log);
  kill(c.pid, SIGINT);
  kill(c.pid, SIGINT);
  // either the second signal ended it at once, or the first one's orderly stop won the race:
  // both exit with 130, neither crashes
  EXPECT_EQ(wait_child(c), 130) << read_file(c.log);
}

TEST(NothingLost, ResumeGivesTheUninterruptedBits) {
  TempDir dir;
  const std::string out = dir / "r.exr";
  const Child c = spawn_tuile(with(kScene, {"--spp", "1000000", "--checkpoint", "0.001", "-o", out}), dir / "log");
  ASSERT_GT(c.pid, 0);
  ASSERT_TRUE(wait_for_file(c, checkpoint_path(out))) << read_file(c.log);
  kill(c.pid, SIGINT);
  ASSERT_EQ(wait_child(c), 130) << read_file(c.log);
  const uint64_t done = load_checkpoint(checkpoint_path(out)).film.samples;
  // two passes more (a pass is 2^23 / pixels samples per pixel here)
  const uint32_t pass = fixed_passes(96 * 64).pass_spp;
  const std::string target = std::to_string(done + 2 * pass);
  ASSERT_EQ(run_tuile(with(kScene, {"--spp", target, "-o", out, "--resume"}), dir / "log2"), 0) << read_file(dir / "log2");
  EXPECT_NE(read_file(dir / "log2").find("resuming"), std::string::npos);
  const std::string ref = dir / "ref.exr";
  ASSERT_EQ(run_tuile(with(kScene, {"--spp", target, "-o", ref, "--quiet"}), dir / "log3"), 0);
  EXPECT_TRUE(same_pixels(out, ref));
  EXPECT_EQ(header_spp(out), std::stoi(target));
  // another seed (or scene) is refused with a message naming what differs
  EXPECT_EQ(run_tuile(with(kScene, {"--spp", target, "--seed", "9", "-o", out, "--resume"}), dir / "log4"), 1);
  EXPECT_NE(read_file(dir / "log4").find("belongs to another render"), std::string::npos) << read_file(dir / "log4");
  // and --resume without a checkpoint is an error
  EXPECT_EQ(run_tuile(with(kScene, {"-o", dir / "none.exr", "--resume"}), dir / "log5"), 1);
  EXPECT_NE(read_file(dir / "log5").find("no checkpoint"), std::string::npos) << read_file(dir / "log5");
}

TEST(NothingLost, SigkillDuringCheckpointsLeavesOneThatResumes) {
  TempDir dir;
  std::mt19937 rng(11);
  // checkpoints after every pass of a 256x256 render (1.4 MB each); killed at moments
  // spread over the checkpoint writes
  // (two rounds in the sanitizer tree, TUILE_TEST_SCALE > 1, where each instrumented
  // process takes seconds)
  for (int round = 0; round < (tuile::test::test_scale > 1 ? 2 : 4); ++round) {
    const std::string out = dir / ("k" + std::to_string(round) + ".exr");
    const Child c = spawn_tuile({"render", "built-in:cornell", "--res", "256x256", "--spp", "1000000", "--checkpoint",
                                 "0.000001", "-o", out, "--quiet"},
                                dir / "log");
    ASSERT_GT(c.pid, 0);
    ASSERT_TRUE(wait_for_file(c, checkpoint_path(out))) << read_file(c.log);
    const auto until = std::chrono::steady_clock::now() + std::chrono::microseconds(rng() % 200000);
    while (std::chrono::steady_clock::now() < until) std::this_thread::yield();
    kill(c.pid, SIGKILL);
    ASSERT_EQ(wait_child(c), 1000 + SIGKILL);
    Checkpoint ck;
    ASSERT_NO_THROW(ck = load_checkpoint(checkpoint_path(out))) << "round " << round;
    EXPECT_GT(ck.film.samples, 0u);
    // and it resumes (two passes further)
    const std::string more = std::to_string(ck.film.samples + 2 * ck.plan.pass_spp);
    EXPECT_EQ(run_tuile({"render", "built-in:cornell", "--res", "256x256", "--spp", more, "-o", out, "--resume", "--quiet"},
                        dir / "log2"),
              0)
        << read_file(dir / "log2");
    EXPECT_EQ(header_spp(out), std::stoi(more));
  }
}

TEST(NothingLost, UnwritableOutputFailsBeforeAnyWork) {
  TempDir dir;
  std::ofstream(dir / "file") << "x";
  for (const std::string& bad :
       {dir / "missing/out.exr", dir / "file/out.exr", dir / "out.png", dir / "out", std::string(dir / ""),
        dir / (std::string(241, 'n') + ".exr")}) {  // (its checkpoint's name would pass 255 bytes)
    const auto t0 = std::chrono::steady_clock::now();
    const int code = run_tuile(with(kScene, {"--spp", "1000000", "-o", bad}), dir / "log");
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    EXPECT_EQ(code, 1) << bad << ": " << read_file(dir / "log");
    EXPECT_LT(seconds, 1.0) << bad;
    EXPECT_NE(read_file(dir / "log").find(bad), std::string::npos) << "the message names the output: " << read_file(dir / "log");
  }
}

// A long output name (its temporary file's name, the name plus ".tmp-PID-N", passed the 255
// bytes a name may have, and every write of it failed: the checkpoints silently) writes its
// image and checkpoints.
TEST(NothingLost, ALongOutputNameWritesItsCheckpoints) {
  TempDir dir;
  const std::string out = dir / (std::string(236, 'n') + ".exr");
  ASSERT_EQ(run_tuile(with(kScene, {"--spp", "4", "--checkpoint", "0.001", "-o", out}), dir / "log"), 0) << read_file(dir / "log");
  EXPECT_EQ(header_spp(out), 4);
  EXPECT_EQ(load_checkpoint(checkpoint_path(out)).film.samples, 4u);
  EXPECT_EQ(read_file(dir / "log").find("warning"), std::string::npos) << read_file(dir / "log");
}

TEST(NothingLost, TargetErrorStopsWithinAFactorOfTwo) {
  TempDir dir;
  // independent samples: the per-pixel variance estimates the error (Sobol' points beat it)
  const std::vector<std::string> scene = {"render", "built-in:cornell", "--res", "48x48", "--sampler", "independent"};
  const std::string ref = dir / "ref.exr";
  // The reference's own noise adds about target * n / n_ref to the measured relMSE (n the
  // spp the render stopped at: 8 and 64 here): 0.2% of the target at full size, 6.3% at
  // TUILE_TEST_SCALE 32 (the sanitizer tree), where the reference has 1/32 of the samples.
  const std::string ref_spp = std::to_string(test::scaled(32768u));
  ASSERT_EQ(run_tuile(with(scene, {"--spp", ref_spp, "--seed", "5", "-o", ref, "--quiet"}), dir / "log"), 0);
  int w = 0, h = 0;
  const std::vector<float> r = read_exr(ref, w, h);
  for (double target : {1e-2, 2e-3}) {
    const std::string out = dir / "t.exr";
    ASSERT_EQ(run_tuile(with(scene, {"--target-error", std::to_string(target), "-o", out}), dir / "log"), 0);
    const std::string log = read_file(dir / "log");
    EXPECT_NE(log.find("below the target"), std::string::npos) << log;
    const int spp = header_spp(out);
    EXPECT_NE(log.find("after " + std::to_string(spp) + " spp"), std::string::npos) << log;
    const std::vector<float> x = read_exr(out, w, h);
    const double actual = relmse(x, r);
    std::printf("  target %.3g: stopped at %d spp, relMSE against the reference %.3g\n", target, spp, actual);
    EXPECT_GT(actual, target / 2) << spp << " spp";
    EXPECT_LT(actual, target * 2) << spp << " spp";
  }
}

// A time budget stops at a pass boundary: whole passes, the bits of an uninterrupted
// render of that many samples (when it stops does not matter to what it holds).
TEST(NothingLost, TimeBudgetStopsAtAPassBoundary) {
  TempDir dir;
  const std::string out = dir / "b.exr";
  ASSERT_EQ(run_tuile(with(kScene, {"--time-budget", "0.3", "-o", out}), dir / "log"), 0) << read_file(dir / "log");
  const ExrMetadata m = read_exr_metadata(out);
  ASSERT_NE(m.find_text("stoppedBy"), nullptr);
  EXPECT_EQ(*m.find_text("stoppedBy"), "time-budget");
  const int spp = header_spp(out);
  const uint32_t pass = fixed_passes(96 * 64).pass_spp;
  ASSERT_GT(spp, 0);
  EXPECT_EQ(spp % static_cast<int>(pass), 0) << spp << " spp in passes of " << pass;
  EXPECT_NE(read_file(dir / "log").find("stopped after " + std::to_string(spp) + " spp"), std::string::npos)
      << read_file(dir / "log");
  const std::string ref = dir / "ref.exr";
  ASSERT_EQ(run_tuile(with(kScene, {"--spp", std::to_string(spp), "-o", ref, "--quiet"}), dir / "log2"), 0);
  EXPECT_TRUE(same_pixels(out, ref));
}

TEST(NothingLost, EveryRenderCarriesItsMetadata) {
  TempDir dir;
  const std::string out = dir / "m.exr";
  ASSERT_EQ(run_tuile(with(kScene, {"--spp", "4", "--seed", "3", "--sampler", "stratified", "-o", out, "--quiet"}),
                      dir / "log"),
            0);
  const ExrMetadata m = read_exr_metadata(out);
  ASSERT_NE(m.find_integer("spp"), nullptr);
  EXPECT_EQ(*m.find_integer("spp"), 4);
  ASSERT_NE(m.find_integer("seed"), nullptr);
  EXPECT_EQ(*m.find_integer("seed"), 3);
  ASSERT_NE(m.find_text("sampler"), nullptr);
  EXPECT_EQ(*m.find_text("sampler"), "stratified");
  ASSERT_NE(m.find_text("estimator"), nullptr);
  EXPECT_NE(m.find_text("estimator")->find("strategy=mis"), std::string::npos);
  ASSERT_NE(m.find_text("tuileVersion"), nullptr);
  EXPECT_EQ(*m.find_text("tuileVersion"), TUILE_VERSION);
  ASSERT_NE(m.find_real("renderSeconds"), nullptr);
  EXPECT_GE(*m.find_real("renderSeconds"), 0.0);
  ASSERT_NE(m.find_text("stoppedBy"), nullptr);
  EXPECT_EQ(*m.find_text("stoppedBy"), "complete");
  // no temporary file is left beside the outputs
  for (const auto& e : fs::directory_iterator(dir.path))
    EXPECT_EQ(e.path().filename().string().find(".tmp-"), std::string::npos) << e.path();
}

TEST(NothingLost, AFailedAtomicWriteKeepsThePreviousFile) {
  TempDir dir;
  const std::string path = dir / "keep.txt";
  std::ofstream(path) << "previous";
  EXPECT_THROW(write_atomically(path,
                                [](const std::string& tmp) {
                                  std::ofstream(tmp) << "half";
                                  throw std::runtime_error("disk full");
                                }),
               std::runtime_error);
  EXPECT_EQ(read_file(path), "previous");
  size_t files = 0;
  for (const auto& e : fs::directory_iterator(dir.path)) {
    (void)e;
    ++files;
  }
  EXPECT_EQ(files, 1u) << "the temporary file is removed";
  write_atomically(path, [](const std::string& tmp) { std::ofstream(tmp) << "new"; });
  EXPECT_EQ(read_file(path), "new");
}

TEST(NothingLost, DamagedCheckpointsAreRefused) {
  TempDir dir;
  const std::string out = dir / "d.exr";
  ASSERT_EQ(run_tuile(with(kScene, {"--spp", "4", "--checkpoint", "1000", "-o", out, "--quiet"}), dir / "log"), 0);
  const std::string ck = checkpoint_path(out);
  ASSERT_NO_THROW(load_checkpoint(ck));
  std::string bytes = read_file(ck);
  {  // cut short
    std::ofstream(ck, std::ios::binary) << bytes.substr(0, bytes.size() / 2);
    EXPECT_THROW(load_checkpoint(ck), std::runtime_error);
  }
  {  // one byte changed
    std::string bad = bytes;
    bad[bad.size() / 3] ^= 0x20;
    std::ofstream(ck, std::ios::binary) << bad;
    EXPECT_THROW(load_checkpoint(ck), std::runtime_error);
  }
  // a valid checksum over a film that disagrees with its fingerprint (another size, other
  // passes, NaN sums: written by hand or by a faulty build) is refused, not resumed
  ASSERT_EQ(run_tuile(with(kScene, {"--spp", "4", "--checkpoint", "1000", "-o", out, "--quiet"}), dir / "log"), 0);
  const Checkpoint c = load_checkpoint(ck);
  for (int k = 0; k < 3; ++k) {
    Film f = c.film;
    PassPlan plan = c.plan;
    if (k == 0) f.reset(c.film.width / 2, c.film.height), f.samples = c.film.samples;
    if (k == 1) plan.pass_spp += 1;
    if (k == 2) f.sum[5] = std::nan("");
    save_checkpoint(ck, c.fingerprint, plan, f);
    ASSERT_NO_THROW(load_checkpoint(ck));
    EXPECT_EQ(run_tuile(with(kScene, {"--spp", "8", "-o", out, "--resume"}), dir / "log"), 1) << k;
    const std::string log = read_file(dir / "log");
    EXPECT_TRUE(log.find("hand-made checkpoint") != std::string::npos || log.find("NaN") != std::string::npos) << log;
  }
  save_checkpoint(ck, c.fingerprint, c.plan, c.film);  // (the checkpoint as it was resumes)
  EXPECT_EQ(run_tuile(with(kScene, {"--spp", "8", "-o", out, "--resume", "--quiet"}), dir / "log"), 0) << read_file(dir / "log");
  std::ofstream(ck, std::ios::binary) << "not a checkpoint at all";
  EXPECT_THROW(load_checkpoint(ck), std::runtime_error);
  EXPECT_EQ(run_tuile(with(kScene, {"--spp", "8", "-o", out, "--resume"}), dir / "log"), 1);
}
