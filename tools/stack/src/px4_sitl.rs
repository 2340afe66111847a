//! `landing run --processes --autopilot px4-sitl --px4 BUILD`: the user's own PX4 SITL
//! build (`make px4_sitl_default`, PX4 v1.16) flies the simulator's world in place of
//! the built-in autopilot. The simulator serves PX4's simulator API (`sim --px4-sitl`)
//! and flies PX4's iris (`--airframe iris`); PX4 runs GPS-denied on the VIO px4-link
//! forwards (ODOMETRY), with the parameters below; the rest of the stack is unchanged.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, Result, bail};
use sim::scenario::LoadedScenario;

/// Where the simulator listens for PX4 (PX4 SITL instance 0 connects to 4560).
pub const SIM_TCP: &str = "127.0.0.1:4560";
/// PX4 SITL instance 0's onboard MAVLink link: it listens on 14580 and sends to 14540,
/// px4-link's port (PX4's `px4-rc.mavlink`, the offboard API's link).
pub const PX4_ONBOARD_PORTS: (u16, u16) = (14580, 14540);

/// A PX4 SITL build directory (`build/px4_sitl_default`).
#[derive(Debug, Clone)]
pub struct Px4Sitl {
    binary: PathBuf,
    etc: PathBuf,
}

impl Px4Sitl {
    /// The build at `dir`: it must hold `bin/px4` and `etc/` (what `make px4_sitl_default`
    /// leaves in `build/px4_sitl_default`).
    pub fn at(dir: &Path) -> Result<Self> {
        let binary = dir.join("bin").join("px4");
        let etc = dir.join("etc");
        if !binary.is_file() || !etc.is_dir() {
            bail!(
                "--px4 {}: not a PX4 SITL build directory (allowed: one holding bin/px4 and etc/, e.g. PX4-Autopilot/build/px4_sitl_default after `make px4_sitl_default`)",
                dir.display()
            );
        }
        Ok(Self { binary, etc })
    }

    /// The parameters the stack needs on PX4, with why (also in docs/px4-sitl.md), for
    /// `scn`: set at boot through PX4's `PX4_PARAM_<NAME>` environment.
    pub fn params(scn: &LoadedScenario) -> Vec<(&'static str, String)> {
        let gps = if scn.scenario.gps.rate_hz > 0.0 {
            "7"
        } else {
            "0"
        };
        vec![
            // Fuse the VIO: horizontal and vertical position, velocity and yaw.
            ("EKF2_EV_CTRL", "15".into()),
            // Height from vision, as the paper's T265 gave it (the barometer drifts).
            ("EKF2_HGT_REF", "3".into()),
            // No GPS unless the scenario has one (`[gps]`): the missions are GPS-denied.
            ("EKF2_GPS_CTRL", gps.into()),
            // px4-link sends no TIMESYNC: PX4 stamps each sample on arrival, so the
            // VIO's own latency is the delay to compensate.
            (
                "EKF2_EV_DELAY",
                format!("{:.0}", scn.scenario.vio.latency_ms),
            ),
            // Land, not hover, when the companion's setpoints stop (deploy/README.md).
            ("COM_OBL_RC_ACT", "4".into()),
            // The airframe's hover thrust (PX4's default 0.5 is another vehicle's): the
            // hover thrust estimator then starts where the vehicle is.
            (
                "MPC_THR_HOVER",
                format!("{:.3}", scn.airframe.hover_thrust_normalized()),
            ),
            // Off the ground at once: PX4's 3 s take-off ramp left the iris on the road
            // 4 s after arming, where the outdoor scenarios' pad vehicle drives past
            // (the built-in autopilot ends its ramp at lift-off).
            ("MPC_TKO_RAMP_T", "0.5".into()),
            // The tilt from the whole acceleration: with PX4's default 1 the drop onto
            // the pad sheds horizontal thrust and drifts downwind (deploy/README.md).
            ("MPC_ACC_DECOUPLE", "0".into()),
            // No RC on this vehicle: no stick input, no RC-loss failsafe to trip.
            ("COM_RC_IN_MODE", "4".into()),
            ("NAV_RCL_ACT", "0".into()),
        ]
    }

    /// PX4 started in daemon mode in `workdir` (fresh: its parameters, dataman and logs
    /// go there), waiting for the simulator on [`SIM_TCP`], flying the iris
    /// (`none_iris`, airframe 10016) with [`Self::params`].
    pub fn command(&self, workdir: &Path, scn: &LoadedScenario) -> Result<Command> {
        std::fs::create_dir_all(workdir)
            .with_context(|| format!("creating {}", workdir.display()))?;
        let mut cmd = Command::new(&self.binary);
        cmd.arg("-d")
            .arg("-w")
            .arg(workdir)
            .arg(&self.etc)
            .env("PX4_SIM_MODEL", "none_iris")
            .env_remove("PX4_SIMULATOR")
            .env_remove("PX4_SYS_AUTOSTART");
        for (name, value) in Self::params(scn) {
            cmd.env(format!("PX4_PARAM_{name}"), value);
        }
        Ok(cmd)
    }

    /// What the graph node `node` runs with besides the graph's arguments: the simulator
    /// serves PX4's simulator API and flies PX4's vehicle; px4-link forwards the VIO.
    pub fn extra_args(node: &str) -> &'static [&'static str] {
        match node {
            "sim" => &["--px4-sitl", SIM_TCP, "--airframe", "iris"],
            "px4-link" => &["--forward-vio"],
            _ => &[],
        }
    }
}
