// field-log's POSE export: poses.csv, the metric trajectories (TUM, one file
// per epoch and trajectory_metric.tum) and the summary, from a small
// hand-written log; malformed POSE lines are skipped and named by file and line.
// Its WINDOW export: windows.csv.

#include "field_log_report.h"

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/drivers/fieldlog/field_log.h>

#include "temp_dir.h"

namespace scaled::tools {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

std::string slurp(const fs::path& path) {
    std::ifstream in(path);
    EXPECT_TRUE(in) << path;
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
}

std::vector<std::string> linesOf(const std::string& text) {
    std::vector<std::string> out;
    std::stringstream s(text);
    for (std::string l; std::getline(s, l);) {
        out.push_back(l);
    }
    return out;
}

// POSE lines as the daemon writes them (docs/field-log.md), members reduced to
// what differs between the cases.
std::string pose(std::int64_t frame, std::int64_t t_ns, int epoch, const std::string& metric,
                 const std::string& orientation = "[1,0,0,0]", const std::string& map = "[1,2,3]") {
    return R"({"class":"POSE","mono_ns":)" + std::to_string(1000 + frame) + R"(,"frame_id":)" +
           std::to_string(frame) + R"(,"t_ns":)" + std::to_string(t_ns) + R"(,"epoch":)" +
           std::to_string(epoch) + R"(,"state":"converging",)" + metric + R"(,"orientation":)" +
           orientation +
           R"(,"attitude_cov":[[1e-05,0,0],[0,1e-05,0],[0,0,1e-05]],"position_map":)" + map +
           R"(,"velocity_map":[0,0,0],"position_map_cov":[[1e-06,0,0],[0,1e-06,0],[0,0,1e-06]]})";
}

const std::string kNoScale =
    R"("scale":null,"scale_sigma":null,"position":null,"velocity":null,"position_cov":null)";

std::string metricAt(double scale, const std::string& position, double sigma_x = 0.02) {
    const std::string var = std::to_string(sigma_x * sigma_x);
    return R"("scale":)" + std::to_string(scale) + R"(,"scale_sigma":0.01,"position":)" + position +
           R"(,"velocity":[0,0,0],"position_cov":[[)" + var + R"(,0,0],[0,0.0009,0],[0,0,0.0016]])";
}

TEST(FieldLogReport, PosesBecomeACsvAndMetricTrajectoriesPerEpoch) {
    test::TempDir dir("field_log_report");
    const fs::path log = dir.path() / "scaled-20240101T000000Z-000001.jsonl";
    {
        std::ofstream out(log);
        out << R"({"class":"START","mono_ns":1,"release":"0.1.0","source":"sim","config":""})"
            << "\n"
            // 2: epoch 1 before its scale: a row, no trajectory pose.
            << pose(3, 100'000'000, 1, kNoScale)
            << "\n"
            // 3, 4: metric.
            << pose(6, 200'000'000, 1, metricAt(1.5, "[1.5,3,4.5]"), "[0.5,-0.5,0.5,-0.5]") << "\n"
            << pose(9, 300'000'000, 1, metricAt(1.5, "[1.5,3,-0.25]"))
            << "\n"
            // 5: malformed position; 6: no orientation; 7: not a unit quaternion.
            << pose(12, 400'000'000, 1, metricAt(1.5, "[1.5,3]")) << "\n"
            << R"({"class":"POSE","mono_ns":9,"frame_id":13,"t_ns":1,"epoch":1,"position_map":[0,0,0]})"
            << "\n"
            << pose(14, 466'666'667, 1, kNoScale, "[2,0,0,0]")
            << "\n"
            // 8: t_ns went back within the epoch: a row, left out of the trajectory.
            << pose(15, 250'000'000, 1, metricAt(1.5, "[0,0,0]"))
            << "\n"
            // 9: a new epoch (a new map, a new frame G): its own trajectory.
            << pose(20, 700'000'000, 2, metricAt(2, "[0,0,1]")) << "\n";
    }
    auto contents = drivers::fieldlog::readFieldLog(log);
    ASSERT_TRUE(contents) << contents.error().message;
    const FieldLogAnalysis a = analyseFieldLog(*contents, log.string());
    EXPECT_EQ(a.classes.at("POSE"), 8U);
    EXPECT_EQ(a.bad_fields, 3U);
    ASSERT_EQ(a.problems.size(), 4U);
    const std::string where = log.string() + ":";
    EXPECT_EQ(a.problems[0], where + "5: POSE position is neither null nor [x,y,z] (skipped)");
    EXPECT_EQ(a.problems[1], where + "6: POSE orientation is not [w,x,y,z] (skipped)");
    EXPECT_EQ(a.problems[2],
              where + "7: POSE orientation is not a unit quaternion (norm 2) (skipped)");
    EXPECT_EQ(a.problems[3], where +
                                 "8: POSE t_ns 250000000 is not after the previous pose of run "
                                 "1 epoch 1 (left out of its trajectory)");
    ASSERT_EQ(a.pose_rows.size(), 5U);
    EXPECT_EQ(a.metric_poses, 4U);
    ASSERT_EQ(a.trajectories.size(), 2U);
    EXPECT_EQ(a.trajectories[0].file, "trajectory_metric_epoch1.tum");
    EXPECT_EQ(a.trajectories[0].poses.size(), 2U);
    EXPECT_EQ(a.trajectories[1].file, "trajectory_metric_epoch2.tum");
    ASSERT_TRUE(a.main_trajectory.has_value());
    EXPECT_EQ(*a.main_trajectory, 0U);

    const fs::path out = dir.path() / "out";
    ASSERT_TRUE(writeFieldLogOutputs(a, out.string()));
    // TUM: t x y z qx qy qz qw, metres in G, camera to G.
    const std::string epoch1 = slurp(out / "trajectory_metric_epoch1.tum");
    EXPECT_EQ(linesOf(epoch1),
              (std::vector<std::string>{
                  "# t tx ty tz qx qy qz qw (camera-to-world, metres, t in seconds)",
                  "0.200000 1.500000000 3.000000000 4.500000000 -0.500000000 0.500000000 "
                  "-0.500000000 0.500000000",
                  "0.300000 1.500000000 3.000000000 -0.250000000 0.000000000 0.000000000 "
                  "0.000000000 1.000000000"}));
    EXPECT_EQ(slurp(out / "trajectory_metric.tum"), epoch1);
    EXPECT_EQ(linesOf(slurp(out / "trajectory_metric_epoch2.tum")),
              (std::vector<std::string>{
                  "# t tx ty tz qx qy qz qw (camera-to-world, metres, t in seconds)",
                  "0.700000 0.000000000 0.000000000 1.000000000 0.000000000 0.000000000 "
                  "0.000000000 1.000000000"}));

    // poses.csv: every valid POSE line, nulls as empty cells.
    EXPECT_EQ(linesOf(slurp(out / "poses.csv")),
              (std::vector<std::string>{
                  std::string("t_s,frame,epoch,x_m,y_m,z_m,sigma_x_m,sigma_y_m,sigma_z_m,"
                              "scale,state,x_map,y_map,z_map,run"),
                  "0.1,3,1,,,,,,,,converging,1,2,3,1",
                  "0.2,6,1,1.5,3,4.5,0.02,0.03,0.04,1.5,converging,1,2,3,1",
                  "0.3,9,1,1.5,3,-0.25,0.02,0.03,0.04,1.5,converging,1,2,3,1",
                  "0.25,15,1,0,0,0,0.02,0.03,0.04,1.5,converging,1,2,3,1",
                  "0.7,20,2,0,0,1,0.02,0.03,0.04,2,converging,1,2,3,1"}));

    const json summary = json::parse(slurp(out / "summary.json"));
    EXPECT_EQ(summary["poses_logged"], 5);
    EXPECT_EQ(summary["metric_poses_logged"], 4);
    EXPECT_EQ(summary["trajectory_metric"], "trajectory_metric_epoch1.tum");
    ASSERT_EQ(summary["trajectories"].size(), 2U);
    EXPECT_EQ(summary["trajectories"][0]["poses"], 2);
    EXPECT_DOUBLE_EQ(summary["trajectories"][0]["path_m"].get<double>(), 4.75);
    EXPECT_EQ(summary["trajectories"][1]["epoch"], 2);
    EXPECT_NE(toText(a).find("5 pose lines (4 metric)"), std::string::npos) << toText(a);
}

// WINDOW lines become windows.csv, one row per window optimisation with the
// camera it used; a line without its frame or epoch is skipped and named.
TEST(FieldLogReport, WindowLinesBecomeACsv) {
    test::TempDir dir("field_log_report");
    const fs::path log = dir.path() / "scaled-20240101T000000Z-000001.jsonl";
    {
        std::ofstream out(log);
        out << R"({"class":"START","mono_ns":1,"release":"0.1.0","source":"sim","config":""})"
            << "\n"
            << R"({"class":"WINDOW","mono_ns":2,"frame_id":136,"t_ns":4533333333,"epoch":1,)"
            << R"("keyframes":46,"free_keyframes":13,"points":310,"observations":3900,)"
            << R"("rms_before_px":1.25,"rms_px":0.5,"scale":1.015625,"rolling_shutter_s":0.0227,)"
            << R"("focal_scale":1,"k1":0})"
            << "\n"
            << R"({"class":"WINDOW","mono_ns":3,"t_ns":5,"keyframes":46})"
            << "\n";
    }
    auto contents = drivers::fieldlog::readFieldLog(log);
    ASSERT_TRUE(contents) << contents.error().message;
    const FieldLogAnalysis a = analyseFieldLog(*contents, log.string());
    EXPECT_EQ(a.classes.at("WINDOW"), 2U);
    EXPECT_EQ(a.bad_fields, 1U);
    ASSERT_EQ(a.problems.size(), 1U);
    EXPECT_EQ(a.problems[0], log.string() + ":3: WINDOW without frame_id or epoch (skipped)");
    const fs::path out = dir.path() / "out";
    ASSERT_TRUE(writeFieldLogOutputs(a, out.string()));
    EXPECT_EQ(linesOf(slurp(out / "windows.csv")),
              (std::vector<std::string>{
                  "frame,t_s,epoch,keyframes,free_keyframes,points,observations,rms_before_px,"
                  "rms_px,scale,rolling_shutter_s,focal_scale,k1,run",
                  "136,4.533333333,1,46,13,310,3900,1.25,0.5,1.015625,0.0227,1,0,1"}));
    EXPECT_EQ(json::parse(slurp(out / "summary.json"))["windows_logged"], 1);
    EXPECT_NE(toText(a).find("1 window lines"), std::string::npos) << toText(a);
}

// Trajectories of several runs carry the run in their names (epochs restart
// with every run); a log without metric poses writes no TUM file.
TEST(FieldLogReport, SeveralRunsNameTheRunAndNoScaleMeansNoTrajectory) {
    test::TempDir dir("field_log_report");
    const fs::path log = dir.path() / "a.jsonl";
    const std::string start =
        R"({"class":"START","mono_ns":1,"release":"0.1.0","source":"sim","config":""})";
    {
        std::ofstream out(log);
        out << start << "\n"
            << pose(1, 100'000'000, 1, metricAt(1, "[0,0,0]")) << "\n"
            << start << "\n"
            << pose(1, 100'000'000, 1, metricAt(1, "[1,0,0]")) << "\n"
            << pose(2, 200'000'000, 1, metricAt(1, "[2,0,0]")) << "\n";
    }
    auto contents = drivers::fieldlog::readFieldLog(log);
    ASSERT_TRUE(contents) << contents.error().message;
    const FieldLogAnalysis a = analyseFieldLog(*contents, log.string());
    EXPECT_TRUE(a.problems.empty());
    ASSERT_EQ(a.trajectories.size(), 2U);
    EXPECT_EQ(a.trajectories[0].file, "trajectory_metric_run1_epoch1.tum");
    EXPECT_EQ(a.trajectories[1].file, "trajectory_metric_run2_epoch1.tum");
    EXPECT_EQ(*a.main_trajectory, 1U);  // the longer one
    const fs::path out = dir.path() / "out";
    ASSERT_TRUE(writeFieldLogOutputs(a, out.string()));
    EXPECT_TRUE(fs::exists(out / "trajectory_metric_run1_epoch1.tum"));
    EXPECT_EQ(linesOf(slurp(out / "trajectory_metric.tum")).size(), 3U);

    const fs::path none = dir.path() / "b.jsonl";
    std::ofstream(none) << start << "\n" << pose(1, 100'000'000, 1, kNoScale) << "\n";
    auto c2 = drivers::fieldlog::readFieldLog(none);
    ASSERT_TRUE(c2) << c2.error().message;
    const FieldLogAnalysis b = analyseFieldLog(*c2, none.string());
    EXPECT_EQ(b.pose_rows.size(), 1U);
    EXPECT_TRUE(b.trajectories.empty());
    const fs::path out2 = dir.path() / "out2";
    ASSERT_TRUE(writeFieldLogOutputs(b, out2.string()));
    EXPECT_TRUE(fs::exists(out2 / "poses.csv"));
    EXPECT_FALSE(fs::exists(out2 / "trajectory_metric.tum"));
    EXPECT_EQ(json::parse(slurp(out2 / "summary.json"))["trajectory_metric"], nullptr);
}

}  // namespace
}  // namespace scaled::tools
