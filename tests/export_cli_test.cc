// `lrfnet export` as a user runs it, read back with independent parsers: the ROS 2 launch file
// with yaml-cpp (static_transform_publisher's own argument names), the URDF with urdfdom (ROS's
// URDF parser), the CSV by hand. The exported transforms, composed back, give the calibration's
// poses: each sensor's world pose, and every pair's relative pose.

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Geometry>
#include <cmath>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#ifdef LRFNET_HAVE_URDFDOM
#include <urdf_parser/urdf_parser.h>
#endif

#include "tests/process_harness.h"

namespace lrfnet {
namespace {

using testing::Process;
using testing::ReadText;
using testing::ScratchDir;

struct Pose {
  double x_m, y_m, yaw_rad;
};

// The calibration every format is checked against (ids that are not frame names on purpose).
const std::map<std::string, Pose> kPoses = {
    {"s1", {0.0, 0.0, 0.0}},
    {"gate-2", {12.25, -3.5, 2.2}},
    {"hall.3", {-4.125, 7.75, -1.3}},
    {"s4", {0.5, 30.0, 3.1}},
};

std::string CalibrationYaml() {
  std::ostringstream out;
  out.precision(17);
  out << "reference: s1\nsensors:\n";
  for (const auto& [id, p] : kPoses) {
    out << "  - {id: \"" << id << "\", x_m: " << p.x_m << ", y_m: " << p.y_m
        << ", yaw_deg: " << p.yaw_rad * 180.0 / M_PI << "}\n";
  }
  out << "  - {id: \"lost\", calibrated: false}\n";
  return out.str();
}

// A 3D transform from x, y, z, roll, pitch, yaw as ROS composes it (R = Rz Ry Rx).
Eigen::Isometry3d Transform(double x, double y, double z, double roll, double pitch, double yaw) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
                Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
                Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
                   .toRotationMatrix();
  t.translation() = Eigen::Vector3d(x, y, z);
  return t;
}

double Wrap(double a) { return std::atan2(std::sin(a), std::cos(a)); }

// Checks parent_from_frame (by frame name) against the calibration: absolute poses, height, and
// the relative pose of every pair composed from two exported transforms.
void ExpectPoses(const std::map<std::string, Eigen::Isometry3d>& exported,
                 const std::map<std::string, std::string>& frame_of, double z_m) {
  ASSERT_EQ(exported.size(), kPoses.size());
  for (const auto& [id, p] : kPoses) {
    ASSERT_EQ(exported.count(frame_of.at(id)), 1u) << id;
    const Eigen::Isometry3d& t = exported.at(frame_of.at(id));
    EXPECT_NEAR(t.translation().x(), p.x_m, 1e-9) << id;
    EXPECT_NEAR(t.translation().y(), p.y_m, 1e-9) << id;
    EXPECT_NEAR(t.translation().z(), z_m, 1e-9) << id;
    const Eigen::Vector3d x_axis = t.linear() * Eigen::Vector3d::UnitX();
    EXPECT_NEAR(Wrap(std::atan2(x_axis.y(), x_axis.x()) - p.yaw_rad), 0.0, 1e-9) << id;
    EXPECT_NEAR((t.linear() * Eigen::Vector3d::UnitZ()).z(), 1.0, 1e-12) << id;
  }
  for (const auto& [a, pa] : kPoses) {
    for (const auto& [b, pb] : kPoses) {
      const Eigen::Isometry3d a_from_b =
          exported.at(frame_of.at(a)).inverse() * exported.at(frame_of.at(b));
      // The same from the calibration in 2D.
      const double c = std::cos(pa.yaw_rad), s = std::sin(pa.yaw_rad);
      const double dx = pb.x_m - pa.x_m, dy = pb.y_m - pa.y_m;
      EXPECT_NEAR(a_from_b.translation().x(), c * dx + s * dy, 1e-9) << a << " " << b;
      EXPECT_NEAR(a_from_b.translation().y(), -s * dx + c * dy, 1e-9) << a << " " << b;
      const Eigen::Vector3d x_axis = a_from_b.linear() * Eigen::Vector3d::UnitX();
      EXPECT_NEAR(Wrap(std::atan2(x_axis.y(), x_axis.x()) - (pb.yaw_rad - pa.yaw_rad)), 0.0, 1e-9);
    }
  }
}

class ExportTest : public ::testing::Test {
 protected:
  void SetUp() override {
    std::ofstream(dir_ / "calibration.yaml") << CalibrationYaml();
    for (const auto& [id, p] : kPoses) {
      std::string frame = id;
      for (char& ch : frame) {
        if (ch == '-' || ch == '.') ch = '_';
      }
      frame_of_[id] = "site/" + frame + "_laser";
    }
  }
  std::string Export(const std::string& format, const std::vector<std::string>& extra = {}) {
    std::vector<std::string> args = {"export",         dir_ / "calibration.yaml",
                                     "--format",       format,
                                     "--parent-frame", "map",
                                     "--frame",        "site/{id}_laser",
                                     "--z-m",          "2.5",
                                     "--out",          dir_ / ("out." + format)};
    args.insert(args.end(), extra.begin(), extra.end());
    Process p(LRFNET_TOOL_BINARY, args);
    EXPECT_EQ(p.Wait(), 0) << p.err();
    return ReadText(dir_ / ("out." + format));
  }
  ScratchDir dir_;
  std::map<std::string, std::string> frame_of_;
};

TEST_F(ExportTest, Ros2StaticTransformsComposeBackToTheCalibration) {
  const YAML::Node launch = YAML::Load(Export("ros2-static-tf"));
  std::map<std::string, Eigen::Isometry3d> exported;
  std::set<std::string> node_names;
  for (const YAML::Node& entry : launch["launch"]) {
    const YAML::Node node = entry["node"];
    EXPECT_EQ(node["pkg"].as<std::string>(), "tf2_ros");
    EXPECT_EQ(node["exec"].as<std::string>(), "static_transform_publisher");
    EXPECT_TRUE(node_names.insert(node["name"].as<std::string>()).second);
    std::istringstream args(node["args"].as<std::string>());
    std::map<std::string, std::string> value;
    for (std::string key, v; args >> key >> v;) value[key] = v;
    EXPECT_EQ(value.at("--frame-id"), "map");
    exported[value.at("--child-frame-id")] =
        Transform(std::stod(value.at("--x")), std::stod(value.at("--y")),
                  std::stod(value.at("--z")), std::stod(value.at("--roll")),
                  std::stod(value.at("--pitch")), std::stod(value.at("--yaw")));
  }
  ExpectPoses(exported, frame_of_, 2.5);
}

TEST_F(ExportTest, UrdfComposesBackToTheCalibration) {
#ifndef LRFNET_HAVE_URDFDOM
  GTEST_SKIP() << "liburdfdom-dev is not installed (scripts/install_deps.sh adds it)";
#else
  const urdf::ModelInterfaceSharedPtr model = urdf::parseURDF(Export("urdf"));
  ASSERT_TRUE(model) << "urdfdom refused the file";
  EXPECT_EQ(model->getName(), "lrfnet_site");
  EXPECT_EQ(model->getRoot()->name, "map");
  std::map<std::string, Eigen::Isometry3d> exported;
  for (const auto& [name, joint] : model->joints_) {
    EXPECT_EQ(joint->type, urdf::Joint::FIXED);
    EXPECT_EQ(joint->parent_link_name, "map");
    const urdf::Pose& o = joint->parent_to_joint_origin_transform;
    double roll = 0, pitch = 0, yaw = 0;
    o.rotation.getRPY(roll, pitch, yaw);
    exported[joint->child_link_name] =
        Transform(o.position.x, o.position.y, o.position.z, roll, pitch, yaw);
  }
  ExpectPoses(exported, frame_of_, 2.5);
#endif
}

TEST_F(ExportTest, CsvHasEveryPoseAndTheUncalibratedOnlyWhenAsked) {
  std::istringstream csv(Export("csv"));
  std::string line;
  std::getline(csv, line);
  EXPECT_EQ(line, "sensor,parent_frame,frame,x_m,y_m,z_m,yaw_deg,yaw_rad,qx,qy,qz,qw,calibrated");
  std::map<std::string, Eigen::Isometry3d> exported;
  while (std::getline(csv, line)) {
    std::vector<std::string> f;
    std::stringstream cells(line);
    for (std::string cell; std::getline(cells, cell, ',');) f.push_back(cell);
    ASSERT_EQ(f.size(), 13u) << line;
    EXPECT_EQ(f[1], "map");
    EXPECT_EQ(f[12], "true");
    const Eigen::Quaterniond q(std::stod(f[11]), std::stod(f[8]), std::stod(f[9]),
                               std::stod(f[10]));
    EXPECT_NEAR(q.norm(), 1.0, 1e-12);
    EXPECT_NEAR(std::stod(f[6]) * M_PI / 180.0, std::stod(f[7]), 1e-9);
    Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
    t.linear() = q.toRotationMatrix();
    t.translation() = Eigen::Vector3d(std::stod(f[3]), std::stod(f[4]), std::stod(f[5]));
    exported[f[2]] = t;
  }
  ExpectPoses(exported, frame_of_, 2.5);
  EXPECT_NE(Export("csv", {"--include-uncalibrated"}).find("lost,map,site/lost_laser"),
            std::string::npos);
}

TEST_F(ExportTest, BadArgumentsAreOneLineErrors) {
  struct Case {
    std::vector<std::string> args;
    int code;
    const char* expected;
  };
  const Case cases[] = {
      {{"export", dir_ / "calibration.yaml"}, 2, "--format"},
      {{"export", dir_ / "calibration.yaml", "--format", "sdf"}, 2, "unknown --format"},
      {{"export", dir_ / "calibration.yaml", "--format", "csv", "--frame", "laser"}, 2, "{id}"},
      {{"export", dir_ / "calibration.yaml", "--format", "csv", "--parent-frame", "a b"},
       2,
       "--parent-frame"},
      {{"export", dir_ / "nope.yaml", "--format", "csv"}, 1, "nope.yaml"},
      {{"export", dir_ / "calibration.yaml", "--format", "csv", "--frame", "x{id}",
        "--parent-frame", "xs1"},
       1,
       "two frames"},
  };
  for (const Case& c : cases) {
    Process p(LRFNET_TOOL_BINARY, c.args);
    EXPECT_EQ(p.Wait(), c.code) << c.expected;
    EXPECT_NE(p.err().find(c.expected), std::string::npos) << p.err();
    EXPECT_EQ(testing::CountLines(p.err()), 1u) << p.err();
  }
}

}  // namespace
}  // namespace lrfnet
