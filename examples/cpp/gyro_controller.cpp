// A lockstep controller for gyro_sim in C++ (rclcpp): the contract of docs/protocol.md.
//
// NOT BUILT in the gyro_sim repository (its CI has the ROS 2 Python wheels only, no rclcpp): it is a
// starting point, to build in a ROS 2 workspace (see README.md next to it).
//
// For each state the simulator publishes (gyro/imu and gyro/kinetic_moment with the same header stamp,
// paired here by stamp) it publishes one gyro/stator_commands JointState carrying that stamp: a simulator in
// lockstep waits for exactly that stamp before it integrates the next control period. Two laws:
//
//   law = "spinup":        stator `stator` at `current` A, field at `target_spin` rad/s: the zero-slip
//                          asymptote of the spin-up, [K] §1 (torque ∝ ν − Ω, so Ω → ν);
//   law = "psi_switching": [K] (3.1), ν_n = ν sign(u_n · e⊥) on the control stators (axes u_n in the case
//                          frame), e⊥ the unit vector of the polar axis x3 projected on the plane normal to
//                          L; the spin stator on at spin_rate; control currents off in the dead band.
//
// Defaults: the nutation_oblate scene's controller section (psi_switching). Replace `law_commands` with your
// own law, or forward the state to firmware and its answer back (keep the stamp).

#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "builtin_interfaces/msg/time.hpp"
#include "geometry_msgs/msg/vector3_stamped.hpp"
#include "rclcpp/rclcpp.hpp"
#include "sensor_msgs/msg/imu.hpp"
#include "sensor_msgs/msg/joint_state.hpp"
#include "std_msgs/msg/string.hpp"

namespace
{
using Vec3 = std::array<double, 3>;

double dot(const Vec3 & a, const Vec3 & b) {return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];}
double norm(const Vec3 & a) {return std::sqrt(dot(a, a));}
Vec3 cross(const Vec3 & a, const Vec3 & b)
{
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}

// x3, the rotor's polar axis, in the case frame, from the attitude quaternion body → case (ROS order x y z w)
Vec3 polar_axis(double x, double y, double z, double w)
{
  return {2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)};
}

struct Command
{
  std::string name;
  double current;  // A, >= 0
  double rate;     // rad/s, signed
};
}  // namespace

class GyroController : public rclcpp::Node
{
public:
  GyroController()
  : Node("gyro_controller_cpp")
  {
    law_ = declare_parameter<std::string>("law", "psi_switching");
    // spinup
    stator_ = declare_parameter<std::string>("stator", "z3");
    target_spin_ = declare_parameter<double>("target_spin", 3141.592653589793);
    current_ = declare_parameter<double>("current", 1.0);
    // psi_switching
    control_stators_ = declare_parameter<std::vector<std::string>>(
      "control_stators", std::vector<std::string>{"z1", "z2"});
    control_axes_ = declare_parameter<std::vector<double>>(
      "control_axes", std::vector<double>{1.0, 0.0, 0.0, 0.0, 1.0, 0.0});
    nu_ = declare_parameter<std::vector<double>>("nu", std::vector<double>{3000.0, 5000.0});
    control_current_ = declare_parameter<double>("control_current", 0.316);
    spin_stator_ = declare_parameter<std::string>("spin_stator", "z3");
    spin_current_ = declare_parameter<double>("spin_current", 0.5);
    spin_rate_ = declare_parameter<double>("spin_rate", 200.0);
    dead_band_ = declare_parameter<double>("dead_band", 0.001);
    const std::size_t k = control_stators_.size();
    if (nu_.size() == 1) {nu_.assign(k, nu_[0]);}
    if (law_ != "spinup" && law_ != "psi_switching") {
      throw std::invalid_argument("law: spinup or psi_switching");
    }
    if (nu_.size() != k || control_axes_.size() != 3 * k) {
      throw std::invalid_argument("nu: 1 or one value per control stator; control_axes: 3 per control stator");
    }

    // QoS of the contract: reliable, keep last 100, volatile; gyro/status transient local (latched)
    const auto qos = rclcpp::QoS(rclcpp::KeepLast(100)).reliable().durability_volatile();
    pub_ = create_publisher<sensor_msgs::msg::JointState>("gyro/stator_commands", qos);
    imu_sub_ = create_subscription<sensor_msgs::msg::Imu>(
      "gyro/imu", qos, [this](sensor_msgs::msg::Imu::ConstSharedPtr m) {
        auto & e = pending_[stamp_ns(m->header.stamp)];
        e.imu = m;
        answer_if_complete(m->header.stamp);
      });
    l_sub_ = create_subscription<geometry_msgs::msg::Vector3Stamped>(
      "gyro/kinetic_moment", qos, [this](geometry_msgs::msg::Vector3Stamped::ConstSharedPtr m) {
        auto & e = pending_[stamp_ns(m->header.stamp)];
        e.L = m;
        answer_if_complete(m->header.stamp);
      });
    status_sub_ = create_subscription<std_msgs::msg::String>(
      "gyro/status", rclcpp::QoS(rclcpp::KeepLast(100)).reliable().transient_local(),
      [this](std_msgs::msg::String::ConstSharedPtr m) {
        if (m->data.rfind("done:", 0) == 0) {done_ = true;}  // the run is over: we may exit
      });
    RCLCPP_INFO(get_logger(), "gyro controller: law %s", law_.c_str());
  }

  bool done() const {return done_;}

private:
  struct Pending
  {
    sensor_msgs::msg::Imu::ConstSharedPtr imu;
    geometry_msgs::msg::Vector3Stamped::ConstSharedPtr L;
  };

  static int64_t stamp_ns(const builtin_interfaces::msg::Time & t)
  {
    return static_cast<int64_t>(t.sec) * 1000000000LL + static_cast<int64_t>(t.nanosec);
  }

  void answer_if_complete(const builtin_interfaces::msg::Time & stamp)
  {
    const auto it = pending_.find(stamp_ns(stamp));
    if (it == pending_.end() || !it->second.imu || !it->second.L) {
      if (pending_.size() > 1000) {pending_.erase(pending_.begin());}  // a half that never came
      return;
    }
    const auto & o = it->second.imu->orientation;
    const auto & v = it->second.L->vector;
    const std::vector<Command> cmds =
      law_commands(polar_axis(o.x, o.y, o.z, o.w), Vec3{v.x, v.y, v.z});
    pending_.erase(it);

    sensor_msgs::msg::JointState out;
    out.header.stamp = stamp;  // the stamp of the state answered: lockstep waits for it
    for (const auto & c : cmds) {
      out.name.push_back(c.name);
      out.effort.push_back(c.current);   // A, finite, >= 0
      out.velocity.push_back(c.rate);    // rad/s (leave velocity empty to keep the rates)
    }
    pub_->publish(out);
  }

  std::vector<Command> law_commands(const Vec3 & x3, const Vec3 & L) const
  {
    if (law_ == "spinup") {
      return {{stator_, current_, target_spin_}};  // [K] §1
    }
    std::vector<Command> out{{spin_stator_, spin_current_, spin_rate_}};
    const double n = norm(L);
    const double theta = n > 0 ? std::atan2(norm(cross(x3, L)), dot(x3, L)) : 0.0;  // nutation angle
    const double pi = std::acos(-1.0);
    bool in_band = n == 0 || theta < dead_band_ || pi - theta < dead_band_;
    Vec3 e_perp{0, 0, 0};
    if (!in_band) {
      const Vec3 y3{L[0] / n, L[1] / n, L[2] / n};
      const double c = dot(x3, y3);
      const Vec3 p{x3[0] - y3[0] * c, x3[1] - y3[1] * c, x3[2] - y3[2] * c};  // x3 on the plane ⟂ L
      const double s = norm(p);
      in_band = s == 0;
      if (s > 0) {e_perp = {p[0] / s, p[1] / s, p[2] / s};}
    }
    for (std::size_t i = 0; i < control_stators_.size(); ++i) {
      const Vec3 u{control_axes_[3 * i], control_axes_[3 * i + 1], control_axes_[3 * i + 2]};
      if (in_band) {
        out.push_back({control_stators_[i], 0.0, nu_[i]});  // control currents off near θ = 0, π
      } else {
        out.push_back({control_stators_[i], control_current_, dot(u, e_perp) >= 0 ? nu_[i] : -nu_[i]});  // [K] (3.1)
      }
    }
    return out;
  }

  std::string law_, stator_, spin_stator_;
  double target_spin_, current_, control_current_, spin_current_, spin_rate_, dead_band_;
  std::vector<std::string> control_stators_;
  std::vector<double> control_axes_, nu_;
  bool done_ = false;
  std::map<int64_t, Pending> pending_;
  rclcpp::Publisher<sensor_msgs::msg::JointState>::SharedPtr pub_;
  rclcpp::Subscription<sensor_msgs::msg::Imu>::SharedPtr imu_sub_;
  rclcpp::Subscription<geometry_msgs::msg::Vector3Stamped>::SharedPtr l_sub_;
  rclcpp::Subscription<std_msgs::msg::String>::SharedPtr status_sub_;
};

int main(int argc, char ** argv)
{
  rclcpp::init(argc, argv);
  auto node = std::make_shared<GyroController>();
  rclcpp::executors::SingleThreadedExecutor executor;
  executor.add_node(node);
  while (rclcpp::ok() && !node->done()) {
    executor.spin_once(std::chrono::milliseconds(100));
  }
  rclcpp::shutdown();  // nothing else to do: the simulator's watchdog takes over if we stop early
  return 0;
}
