//! `avatarm bench network`: what the network does to the pouring task. Each cell of the grid
//! (one-way delay × loss × mapping mode × trial) runs the two sites in this process — the
//! robot site's control loop on its thread, the operator's hand and twin on this one — over
//! real Zenoh sessions whose traffic passes the seeded impairment relay
//! ([`avatarm_net::impair`]): TCP where nothing is lost (delay only), UDP where datagrams are
//! dropped. The paper's measure (position and orientation RMSE of the real bottle against its
//! twin of the same moment) goes to CSV and a chart against the delay, with the paper's
//! published RMSE as a line.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use avatarm_core::teleop::mapping::MappingMode;
use avatarm_mapping::pouring::PUBLISHED;
use avatarm_net::impair::{Impairment, Relay};
use avatarm_net::{Keys, NetConfig, OperatorSite, RobotSite, Role, SiteClock};
use avatarm_scene::Scene;
use plotters::coord::Shift;
use plotters::prelude::*;
use serde::Serialize;

use super::chart::{Chart, axes, drawing_error, legend, padded, save_chart, write_table};
use crate::AppError;
use crate::net::serve::{ControlLoop, ServeReport};
use crate::teleop::{RobotChoice, trial_parts};

/// The grid `bench network` runs.
#[derive(Debug, Clone)]
pub struct NetworkSweep {
    /// One-way delays (ms), each direction.
    pub delays_ms: Vec<f64>,
    /// Datagram loss (%), each direction; 0 runs over TCP, more over UDP.
    pub losses_pct: Vec<f64>,
    /// Mapping modes.
    pub modes: Vec<MappingMode>,
    /// Trials per cell (the task's seeded hands 0..trials).
    pub trials: u32,
    /// The robot site's watchdog timeout (s).
    pub target_timeout_s: f64,
    /// Show a progress bar.
    pub progress: bool,
}

impl Default for NetworkSweep {
    fn default() -> Self {
        Self {
            delays_ms: vec![0.0, 25.0, 50.0, 100.0, 200.0],
            losses_pct: vec![0.0, 1.0, 5.0],
            modes: vec![MappingMode::Paper, MappingMode::ClosedLoop],
            trials: 10,
            target_timeout_s: 0.5,
            progress: false,
        }
    }
}

/// One trial in one cell.
#[derive(Debug, Clone, Serialize)]
pub struct NetworkTrial {
    /// Mapping mode.
    pub mode: MappingMode,
    /// One-way delay (ms).
    pub delay_ms: f64,
    /// Loss (%).
    pub loss_pct: f64,
    /// Transport (`tcp` or `udp`).
    pub transport: &'static str,
    /// Trial (hand seed).
    pub trial: u32,
    /// Position RMSE (mm), the real bottle against the twin of the same moment.
    pub pos_rmse_mm: f64,
    /// Roll, pitch, yaw RMSE (degrees).
    pub roll_rmse_deg: f64,
    /// See `roll_rmse_deg`.
    pub pitch_rmse_deg: f64,
    /// See `roll_rmse_deg`.
    pub yaw_rmse_deg: f64,
    /// The gripper closed.
    pub grasped: bool,
    /// Highest lift of the real bottle (mm).
    pub real_lift_mm: f64,
    /// Targets the robot site used, and those the operator sent.
    pub targets_used: u64,
    /// Targets sent.
    pub targets_sent: u64,
    /// Stops of the arm after the grasp (stale targets, refusals).
    pub stops_after_grasp: usize,
    /// Median age of the targets used (ms).
    pub target_age_ms: f64,
    /// The operator's measured round trip (ms).
    pub rtt_ms: f64,
    /// Why the trial could not run (the session could not be opened), if it could not.
    pub failed: Option<String>,
}

/// What `bench network` wrote.
#[derive(Debug, Clone)]
pub struct NetworkOutputs {
    /// Every trial.
    pub trials: Vec<NetworkTrial>,
    /// The CSV.
    pub csv: PathBuf,
    /// The chart.
    pub svg: PathBuf,
    /// The chart.
    pub png: PathBuf,
}

fn free_port(udp: bool) -> Result<u16, AppError> {
    let port = if udp {
        std::net::UdpSocket::bind("127.0.0.1:0").and_then(|s| s.local_addr())
    } else {
        std::net::TcpListener::bind("127.0.0.1:0").and_then(|l| l.local_addr())
    };
    port.map(|a| a.port())
        .map_err(|e| AppError::command("bench network", format!("no free port on 127.0.0.1: {e}")))
}

/// One trial through the relay.
fn run_cell(
    scene: &Scene,
    sweep: &NetworkSweep,
    mode: MappingMode,
    delay_ms: f64,
    loss_pct: f64,
    trial: u32,
) -> Result<NetworkTrial, AppError> {
    let udp = loss_pct > 0.0;
    let transport = if udp { "udp" } else { "tcp" };
    let port = free_port(udp)?;
    let keys = Keys::new("bench")?;
    let config = |role: Role, endpoint: String| NetConfig {
        role,
        keys: keys.clone(),
        listen: if role == Role::RobotSite {
            vec![endpoint.clone()]
        } else {
            vec![]
        },
        connect: if role == Role::RobotSite {
            vec![]
        } else {
            vec![endpoint]
        },
        credentials: None,
        dictionary: None,
        operators: vec![],
        robot_sites: vec![],
        tls: None,
        insecure_lan: true,
    };
    let (mut parts, mode) =
        trial_parts(scene, RobotChoice::Sim, Some(mode), trial, "bench network")?;
    parts
        .teleop
        .set_watchdog_timeout(sweep.target_timeout_s)
        .map_err(|e| AppError::flag("--target-timeout", e.to_string()))?;
    // No access control on the bench's loopback: no operators named.
    let info =
        crate::net::serve::robot_info(scene, &parts, sweep.target_timeout_s, vec![], Vec::new())?;
    let mut site = RobotSite::open(
        &config(Role::RobotSite, format!("{transport}/127.0.0.1:{port}")),
        &info,
        SiteClock::start(),
    )?;
    let impairment = Impairment {
        delay_s: delay_ms / 1e3,
        loss: loss_pct / 100.0,
        seed: 1 + u64::from(trial),
        ..Impairment::default()
    };
    let upstream = format!("127.0.0.1:{port}")
        .parse()
        .map_err(|e| AppError::command("bench network", format!("{e}")))?;
    let relay = if udp {
        Relay::udp(upstream, impairment)
    } else {
        Relay::tcp(upstream, impairment)
    }
    .map_err(|e| AppError::command("bench network", format!("the impairment relay: {e}")))?;
    let start_z = scene
        .trial
        .as_ref()
        .map_or(0.0, |s| s.bottle_centre().translation.z);
    let control = ControlLoop {
        teleop: parts.teleop,
        start_z,
        period: parts.period,
        mode,
        scene: scene.file.name.clone(),
        ros2: None,
    };
    let stop = Arc::new(AtomicBool::new(false));
    let loop_stop = stop.clone();
    let robot = std::thread::Builder::new()
        .name("bench robot site".into())
        .spawn(move || {
            let report = control.run(&mut site, None, &loop_stop, Vec::new());
            site.close();
            report
        })
        .map_err(|e| {
            AppError::command("bench network", format!("cannot start the robot site: {e}"))
        })?;
    let joined = OperatorSite::join(
        &config(
            Role::Operator,
            format!("{transport}/{}", relay.local_addr()),
        ),
        Duration::from_secs(20),
    );
    let operated = joined.map(|mut op| {
        let rtt = op.offset().rtt_s;
        let r = crate::net::join::operate(&mut op, scene, Some(mode), trial, None);
        op.close();
        r.map(|r| (r, rtt))
    });
    std::thread::sleep(Duration::from_millis(300));
    stop.store(true, Ordering::Relaxed);
    let report: ServeReport = robot
        .join()
        .map_err(|_| AppError::command("bench network", "the robot site's loop panicked"))?;
    drop(relay);
    let (op, rtt_s) = match operated {
        Ok(r) => r?,
        // The session itself failed (a handshake lost for good on a lossy link): the trial is
        // recorded as failed, with the reason, and the grid goes on.
        Err(e) => {
            return Ok(NetworkTrial {
                mode,
                delay_ms,
                loss_pct,
                transport,
                trial,
                pos_rmse_mm: f64::NAN,
                roll_rmse_deg: f64::NAN,
                pitch_rmse_deg: f64::NAN,
                yaw_rmse_deg: f64::NAN,
                grasped: false,
                real_lift_mm: report.trial.real_lift_m * 1e3,
                targets_used: report.targets_used,
                targets_sent: 0,
                stops_after_grasp: 0,
                target_age_ms: f64::NAN,
                rtt_ms: f64::NAN,
                failed: Some(e.to_string()),
            });
        }
    };
    let t = &report.trial;
    let rpy = t.rpy_rmse_deg.unwrap_or([f64::NAN; 3]);
    let grasp = t.grasp_at_s.unwrap_or(f64::INFINITY);
    Ok(NetworkTrial {
        mode,
        delay_ms,
        loss_pct,
        transport,
        trial,
        pos_rmse_mm: t.pos_rmse_m.map_or(f64::NAN, |v| v * 1e3),
        roll_rmse_deg: rpy[0],
        pitch_rmse_deg: rpy[1],
        yaw_rmse_deg: rpy[2],
        grasped: t.grasp_at_s.is_some(),
        real_lift_mm: t.real_lift_m * 1e3,
        targets_used: report.targets_used,
        targets_sent: op.targets_sent,
        stops_after_grasp: report
            .stops
            .iter()
            .filter(|s| s.t_s > grasp && !s.reason.contains("no operator"))
            .count(),
        target_age_ms: report.target_age_ms.median,
        rtt_ms: rtt_s * 1e3,
        failed: None,
    })
}

/// Runs the grid on `scene`'s task, writes `network_rmse.csv` and the chart into `out`.
pub fn run_network(
    scene: &Scene,
    sweep: &NetworkSweep,
    out: &Path,
) -> Result<NetworkOutputs, AppError> {
    if scene.file.task.is_none() {
        return Err(AppError::flag(
            "SCENE",
            format!("the scene '{}' has no [task]", scene.file.name),
        ));
    }
    for &d in &sweep.delays_ms {
        if !(d.is_finite() && (0.0..=2000.0).contains(&d)) {
            return Err(AppError::flag(
                "--delays",
                format!("{d} ms is not in 0..=2000"),
            ));
        }
    }
    for &l in &sweep.losses_pct {
        if !(l.is_finite() && (0.0..=50.0).contains(&l)) {
            return Err(AppError::flag(
                "--losses",
                format!("{l} % is not in 0..=50"),
            ));
        }
    }
    std::fs::create_dir_all(out).map_err(|e| AppError::write(out, e))?;
    let cells = sweep.modes.len() * sweep.delays_ms.len() * sweep.losses_pct.len();
    let bar = crate::progress::bar(
        (cells as u64) * u64::from(sweep.trials),
        "network",
        sweep.progress,
    );
    let mut trials = Vec::new();
    for &mode in &sweep.modes {
        for &loss in &sweep.losses_pct {
            for &delay in &sweep.delays_ms {
                for trial in 0..sweep.trials {
                    bar.set_message(format!("{} {delay} ms {loss} % trial {trial}", mode.name()));
                    trials.push(run_cell(scene, sweep, mode, delay, loss, trial)?);
                    bar.inc(1);
                }
            }
        }
    }
    bar.finish_and_clear();
    let csv = out.join("network_rmse.csv");
    write_table(
        &csv,
        "mode,delay_ms,loss_pct,transport,trial,pos_rmse_mm,roll_rmse_deg,pitch_rmse_deg,\
yaw_rmse_deg,grasped,real_lift_mm,targets_used,targets_sent,stops_after_grasp,target_age_ms,rtt_ms,\
failed",
        trials.iter().map(|t| {
            format!(
                "{},{},{},{},{},{:.3},{:.3},{:.3},{:.3},{},{:.1},{},{},{},{:.1},{:.2},{}",
                t.mode.name(),
                t.delay_ms,
                t.loss_pct,
                t.transport,
                t.trial,
                t.pos_rmse_mm,
                t.roll_rmse_deg,
                t.pitch_rmse_deg,
                t.yaw_rmse_deg,
                t.grasped,
                t.real_lift_mm,
                t.targets_used,
                t.targets_sent,
                t.stops_after_grasp,
                t.target_age_ms,
                t.rtt_ms,
                t.failed.as_deref().unwrap_or("").replace([',', '\n'], " ")
            )
        }),
    )?;
    let svg = out.join("network_rmse.svg");
    let png = out.join("network_rmse.png");
    let title = format!(
        "Pouring over the network: real bottle against its twin ({}, {} trial(s) per point)",
        scene.file.name, sweep.trials
    );
    save_chart(
        &NetworkChart {
            trials: &trials,
            title: &title,
        },
        (1000, 620),
        &svg,
        &png,
    )?;
    Ok(NetworkOutputs {
        trials,
        csv,
        svg,
        png,
    })
}

/// Mean and sample standard deviation of the finite values.
pub fn mean_std(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let v: Vec<f64> = values.filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = if v.len() > 1 {
        v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)
    } else {
        0.0
    };
    (mean, var.sqrt())
}

struct NetworkChart<'a> {
    trials: &'a [NetworkTrial],
    title: &'a str,
}

impl Chart for NetworkChart<'_> {
    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> Result<(), AppError>
    where
        DB::ErrorType: 'static,
    {
        let err = drawing_error::<DB::ErrorType>;
        root.fill(&WHITE).map_err(err)?;
        let root = root.titled(self.title, ("sans-serif", 20)).map_err(err)?;
        let paper_mm = PUBLISHED.pos_rmse_m.mean * 1e3;
        let x = padded(self.trials.iter().map(|t| t.delay_ms));
        let y = padded(
            self.trials
                .iter()
                .map(|t| t.pos_rmse_mm)
                .chain([0.0, paper_mm]),
        );
        let mut chart = axes(
            &root,
            x,
            (0.0_f64.max(y.0), y.1),
            "one-way delay (ms)",
            "position RMSE (mm)",
        )?;
        chart
            .draw_series(LineSeries::new(
                [(x.0, paper_mm), (x.1, paper_mm)],
                BLACK.stroke_width(1),
            ))
            .map_err(err)?
            .label(format!("paper, one site ({paper_mm:.1} mm)"))
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], BLACK));
        let mut keys: Vec<(MappingMode, f64)> = Vec::new();
        for t in self.trials {
            if !keys.contains(&(t.mode, t.loss_pct)) {
                keys.push((t.mode, t.loss_pct));
            }
        }
        for (i, &(mode, loss)) in keys.iter().enumerate() {
            let colour = Palette99::pick(i).to_rgba();
            let mut delays: Vec<f64> = self
                .trials
                .iter()
                .filter(|t| t.mode == mode && t.loss_pct == loss)
                .map(|t| t.delay_ms)
                .collect();
            delays.sort_by(f64::total_cmp);
            delays.dedup();
            let points: Vec<(f64, f64, f64)> = delays
                .iter()
                .map(|&d| {
                    let (m, s) = mean_std(
                        self.trials
                            .iter()
                            .filter(|t| t.mode == mode && t.loss_pct == loss && t.delay_ms == d)
                            .map(|t| t.pos_rmse_mm),
                    );
                    (d, m, s)
                })
                .filter(|p| p.1.is_finite())
                .collect();
            chart
                .draw_series(LineSeries::new(
                    points.iter().map(|p| (p.0, p.1)),
                    colour.stroke_width(2),
                ))
                .map_err(err)?
                .label(format!("{}, loss {loss} %", mode.name()))
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(2))
                });
            chart
                .draw_series(
                    points.iter().map(|p| {
                        PathElement::new(vec![(p.0, p.1 - p.2), (p.0, p.1 + p.2)], colour)
                    }),
                )
                .map_err(err)?;
            chart
                .draw_series(
                    points
                        .iter()
                        .map(|p| Circle::new((p.0, p.1), 4, colour.filled())),
                )
                .map_err(err)?;
        }
        legend(&mut chart, SeriesLabelPosition::UpperLeft)
    }
}
