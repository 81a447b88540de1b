// scaled --check-config (config_check.h): every problem of a configuration,
// each at its line and key, and what start-up would fail on besides the
// syntax (priors, the socket's group and directory, the replay dataset, the
// log directory). The command-line side is tests/cli/scaled_check_config_cli.sh.

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/daemon/config_check.h>
#include <scaled/daemon/daemon_config.h>

#include "temp_dir.h"

namespace scaled::daemon {
namespace {

void write(const std::filesystem::path& p, const std::string& text) {
    std::ofstream(p) << text;
}

std::string joined(const std::vector<std::string>& lines) {
    std::string out;
    for (const auto& l : lines) {
        out += l + "\n";
    }
    return out;
}

CommandLine withFile(const std::filesystem::path& file) {
    CommandLine cli;
    cli.config = file;
    return cli;
}

TEST(ConfigCheck, EveryProblemOfTheFileAndTheCommandLineIsReportedAtItsLine) {
    test::TempDir tmp("check");
    const auto file = tmp.path() / "c.toml";
    write(file,
          "[source]\nspeed = 0\n[tracker]\nsigma_a = \"fast\"\n[nosuch]\nx = 1\n"
          "[log]\nmax_file_bytes = 1000000\nmax_total_bytes = 500000\n");
    CommandLine cli = withFile(file);
    cli.sets = {"detection.every_frames=0", "socket.max_clients=2000"};
    const CheckedConfig checked = checkDaemonConfig(cli, {});
    std::vector<std::string> messages;
    for (const auto& e : checked.errors) {
        messages.push_back(e.message);
    }
    const std::string all = joined(messages);
    ASSERT_EQ(messages.size(), 6U) << all;
    const std::string f = file.string();
    EXPECT_NE(all.find(f + ":2: source.speed: must be a number in (0, 1000] (got 0)"),
              std::string::npos)
        << all;
    EXPECT_NE(all.find(f + ":4: tracker.sigma_a: "), std::string::npos) << all;
    EXPECT_NE(all.find(f + ":5: nosuch: unknown section"), std::string::npos) << all;
    EXPECT_NE(all.find(f + ":9: log.max_total_bytes: must be >= log.max_file_bytes = 1000000 "
                           "(got 500000)"),
              std::string::npos)
        << all;
    EXPECT_NE(all.find("--set detection.every_frames=0: detection.every_frames: must be an "
                       "integer in [1, 100000] (got 0)"),
              std::string::npos)
        << all;
    EXPECT_NE(all.find("--set socket.max_clients=2000: socket.max_clients: "), std::string::npos)
        << all;
    // Loading stops at the first of them, as it always did.
    EXPECT_FALSE(loadDaemonConfig(cli, {}).ok());
}

TEST(ConfigCheck, AKeyWithAWrongValueIsNotAlsoBlamedForItsDefault) {
    test::TempDir tmp("check");
    const auto file = tmp.path() / "c.toml";
    // fx_px refused: the cross-field rule "a live source needs fx_px > 0"
    // would fire on the default 0 and blame the same key again.
    write(file,
          "[source]\nkind = \"v4l2\"\ndevice = \"/dev/video0\"\n[camera]\nfx_px = \"x\"\n"
          "fy_px = 500\ncx_px = 320\ncy_px = 240\n");
    const CheckedConfig checked = checkDaemonConfig(withFile(file), {});
    ASSERT_EQ(checked.errors.size(), 1U) << checked.errors.front().message;
    EXPECT_NE(checked.errors[0].message.find(":5: camera.fx_px: "), std::string::npos);
}

TEST(ConfigCheck, WhatStartUpNeedsIsCheckedWithoutCreatingAnything) {
    test::TempDir tmp("check");
    const auto file = tmp.path() / "c.toml";
    write(file,
          "[source]\nkind = \"replay\"\nreplay = \"no-such-dataset\"\n"
          "[detector]\nmodel = \"no-model.onnx\"\n"
          "[estimator]\npriors = \"priors.toml\"\n"
          "[socket]\npath = \"" +
              (tmp.path() / "no-dir" / "s.sock").string() +
              "\"\ngroup = \"nosuchgrp-scaled\"\n"
              "[log]\ndir = \"" +
              (tmp.path() / "a-file" / "log").string() + "\"\n");
    write(tmp.path() / "a-file", "not a directory\n");
    const ConfigCheckReport report = checkConfiguration(withFile(file), {});
    const std::string all = joined(report.errors);
    const std::string f = file.string();
    EXPECT_FALSE(report.ok());
    ASSERT_EQ(report.errors.size(), 6U) << all;
    EXPECT_NE(all.find(f + ":3: source.replay: "), std::string::npos) << all;
    EXPECT_NE(all.find(f + ":5: detector.model: "), std::string::npos) << all;
    EXPECT_NE(all.find(f + ":7: estimator.priors: " + (tmp.path() / "priors.toml").string() +
                       ": cannot open priors file"),
              std::string::npos)
        << all;
    EXPECT_NE(all.find(f + ":10: socket.group: "), std::string::npos) << all;
    EXPECT_NE(all.find("unknown group 'nosuchgrp-scaled' (got \"nosuchgrp-scaled\")"),
              std::string::npos)
        << all;
    EXPECT_NE(all.find(f + ":9: socket.path: the directory \"" + (tmp.path() / "no-dir").string() +
                       "\" does not exist"),
              std::string::npos)
        << all;
    EXPECT_NE(all.find(f + ":12: log.dir: cannot create "), std::string::npos) << all;
    EXPECT_FALSE(std::filesystem::exists(tmp.path() / "no-dir"));
}

TEST(ConfigCheck, AGoodConfigurationPassesAndNotesWhatTheUnitMakes) {
    test::TempDir tmp("check");
    const auto file = tmp.path() / "c.toml";
    std::filesystem::copy_file(std::filesystem::path(SCALED_SOURCE_DIR) / "config" / "priors.toml",
                               tmp.path() / "priors.toml");
    write(file, "[estimator]\npriors = \"priors.toml\"\n[socket]\npath = \"" +
                    (tmp.path() / "s.sock").string() + "\"\n[log]\ndir = \"" +
                    (tmp.path() / "log" / "sub").string() + "\"\n");
    const ConfigCheckReport report = checkConfiguration(withFile(file), {});
    EXPECT_TRUE(report.ok()) << joined(report.errors);
    EXPECT_EQ(report.file, std::filesystem::absolute(file).lexically_normal());
    EXPECT_FALSE(std::filesystem::exists(tmp.path() / "log")) << "the check creates nothing";
    EXPECT_FALSE(std::filesystem::exists(tmp.path() / "s.sock"));
}

TEST(ConfigCheck, AnUnreadableFileIsTheOnlyProblemReported) {
    test::TempDir tmp("check");
    const ConfigCheckReport report = checkConfiguration(withFile(tmp.path() / "none.toml"), {});
    ASSERT_EQ(report.errors.size(), 1U) << joined(report.errors);
    EXPECT_NE(report.errors[0].find("none.toml: cannot read configuration"), std::string::npos)
        << report.errors[0];
}

TEST(ConfigCheck, TheSocketGroupIsCheckedWhenSet) {
    SocketConfig s;
    EXPECT_TRUE(checkSocketGroup(s).ok());
    s.group = "root";
    EXPECT_TRUE(checkSocketGroup(s).ok());
    s.group = "nosuchgrp-scaled";
    auto r = checkSocketGroup(s);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().code, core::ErrorCode::kNotFound);
}

}  // namespace
}  // namespace scaled::daemon
