// The daemon on real data: `scaled --source replay:redkitchen --pacing fast`
// with YOLOX-Nano, watched over its socket until the replay ends and the
// daemon exits (at_end = exit). Skips when ../shared (data or model) is absent.

#include <csignal>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include <gtest/gtest.h>

#include "daemon_harness.h"
#include "shared_data.h"
#include "temp_dir.h"

namespace scaled::test {
namespace {

namespace fs = std::filesystem;

TEST(DaemonReplay, RedkitchenConvergesBeforeItExitsCleanly) {
    SCALED_REQUIRE_DATASET(dataset, "redkitchen");
    SCALED_REQUIRE_MODEL(model, "yolox_nano.onnx");
    TempDir tmp("d");
    DaemonUnderTest daemon(SCALED_BIN, tmp.path());
    writeFile(
        daemon.paths().config,
        daemonConfigText(daemon.paths(), fs::path(SCALED_SOURCE_DIR) / "config" / "priors.toml"));
    DaemonOptions opt;
    opt.args = {
        "--source", "replay:" + dataset.string(), "--pacing", "fast",
        "--set",    "source.at_end=exit",         "--set",    "detector.model=" + model.string()};
    opt.ready_timeout = Millis(60'000);
    ASSERT_TRUE(daemon.start(opt));

    auto c = daemon.client();
    ASSERT_TRUE(c.has_value()) << "no VERSION greeting";
    ASSERT_TRUE(c->send(Json{{"cmd", "watch"}, {"enable", true}}));
    std::optional<Json> converged;
    std::optional<Json> last;
    std::optional<Json> status;
    std::int64_t last_frame = -1;
    // The daemon closes the connection when it exits at the end of the replay.
    const auto deadline = Clock::now() + Millis(900'000);
    while (true) {
        auto j = c->readJson(Millis(msLeft(deadline)));
        if (!j) {
            break;
        }
        ASSERT_TRUE(j->is_object()) << c->lastLine();
        if ((*j)["class"] == "STATUS") {
            status = j;
            continue;
        }
        if ((*j)["class"] != "SCALE") {
            continue;
        }
        EXPECT_GE((*j)["frame_id"].get<std::int64_t>(), last_frame);
        last_frame = (*j)["frame_id"].get<std::int64_t>();
        if ((*j)["state"] == "converged" && !converged) {
            converged = j;
            ASSERT_TRUE(c->send(Json{{"cmd", "status"}}));
        }
        last = j;
    }
    ASSERT_TRUE(c->eof()) << "the replay did not end within 900 s";
    const auto code = daemon.process().wait(Millis(60'000));
    ASSERT_TRUE(code.has_value()) << "scaled did not exit after the end of the replay";
    EXPECT_EQ(*code, 0);
    EXPECT_TRUE(daemon.notify().waitFor("STOPPING=1", Millis(0))) << daemon.notify().history();
    ASSERT_TRUE(converged.has_value())
        << "never converged; last SCALE: " << (last ? last->dump() : std::string("none"));
    const double s = (*converged)["scale"].get<double>();
    const double lo = (*converged)["ci95"][0].get<double>();
    const double hi = (*converged)["ci95"][1].get<double>();
    EXPECT_GT(s, 0);
    EXPECT_LE(lo, s);
    EXPECT_GE(hi, s);
    EXPECT_LT((hi - lo) / s, 0.10) << converged->dump();
    // Lossless: nothing dropped, every 10th frame detected (a few may be in flight).
    ASSERT_TRUE(status.has_value()) << "no STATUS reply after convergence";
    EXPECT_EQ((*status)["frames"]["dropped"], 0) << status->dump();
    const auto tracked = (*status)["frames"]["tracked"].get<std::int64_t>();
    EXPECT_GE((*status)["detector"]["runs"].get<std::int64_t>(), tracked / 10 - 3)
        << status->dump();
    EXPECT_EQ((*status)["detector"]["skipped"], 0) << status->dump();
    EXPECT_EQ((*status)["frames_total"].get<std::int64_t>(), 600) << status->dump();
    // docs/accuracy.md: 0.976 against a ground-truth scale of 0.992.
    EXPECT_NEAR(s, 0.992, 0.992 * 0.05) << converged->dump();
    // The estimate goes on after convergence, to the end of the sequence.
    ASSERT_TRUE(last.has_value());
    EXPECT_GT((*last)["observations"].get<std::int64_t>(),
              (*converged)["observations"].get<std::int64_t>())
        << last->dump();
    EXPECT_FALSE(fs::exists(fs::symlink_status(daemon.paths().socket)));
}

}  // namespace
}  // namespace scaled::test
