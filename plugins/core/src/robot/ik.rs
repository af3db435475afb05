//! Damped-least-squares velocity IK with joint position and velocity limits.
//!
//! One step maps a desired twist `[v; ω]` to joint velocities:
//!
//! 1. Damping adapts to the smallest singular value σ of the Jacobian: λ² = 0 while σ ≥ ε and
//!    λ² = (1 − (σ/ε)²)·λ_max² below it, so the solution is exact away from singularities and
//!    bounded near them.
//! 2. Joints whose velocity would cross a position limit within `dt` are saturated at the
//!    velocity that stops them on the limit, removed from the free set, and the rest is solved
//!    again for the remaining twist (a small active-set loop).
//! 3. If any joint still exceeds its velocity limit the whole vector is scaled down uniformly,
//!    which keeps the direction of motion.
//!
//! A Jacobian or twist with NaN/inf gives zero velocities, flagged in [`IkStep::rejected`].

use nalgebra::{DMatrix, DVector, Isometry3, Matrix6xX, Vector3, Vector6};

use crate::robot::kinematics::{Frame, pose_difference};
use crate::robot::{JointLimits, LinkId, RobotModel};

/// Settings of [`dls_step`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DlsSettings {
    /// Largest damping λ_max, reached at a singularity.
    pub max_damping: f64,
    /// Singular value ε below which damping starts.
    pub singular_threshold: f64,
    /// Look-ahead time (s) for the position-limit check: usually the control period.
    pub dt: f64,
}

impl Default for DlsSettings {
    fn default() -> Self {
        Self {
            max_damping: 0.05,
            singular_threshold: 0.05,
            dt: 0.01,
        }
    }
}

/// The result of one IK step.
#[derive(Debug, Clone, PartialEq)]
pub struct IkStep {
    /// Joint velocities.
    pub qdot: DVector<f64>,
    /// Uniform scale applied for velocity limits (1 when none was hit).
    pub scale: f64,
    /// Joints saturated at a position limit.
    pub saturated: Vec<bool>,
    /// Smallest singular value of the Jacobian.
    pub sigma_min: f64,
    /// Damping λ used.
    pub damping: f64,
    /// The inputs had NaN or infinite values; `qdot` is zero.
    pub rejected: bool,
}

/// One damped-least-squares step: joint velocities that best produce `twist` at `q`.
///
/// ```
/// use avatarm_core::robot::ik::{dls_step, DlsSettings};
/// use avatarm_core::robot::JointLimits;
/// use nalgebra::{Matrix6xX, Vector6};
/// // A single prismatic joint along x: the x-velocity is reproduced exactly.
/// let mut j = Matrix6xX::zeros(1);
/// j[(0, 0)] = 1.0;
/// let lim = [JointLimits { lower: -1.0, upper: 1.0, velocity: 1.0, effort: 1.0 }];
/// let step = dls_step(&j, &Vector6::new(0.2, 0.0, 0.0, 0.0, 0.0, 0.0), &[0.0], &lim, &DlsSettings::default());
/// assert!((step.qdot[0] - 0.2).abs() < 1e-12);
/// ```
pub fn dls_step(
    jacobian: &Matrix6xX<f64>,
    twist: &Vector6<f64>,
    q: &[f64],
    limits: &[JointLimits],
    settings: &DlsSettings,
) -> IkStep {
    let n = jacobian.ncols();
    let zero = |rejected| IkStep {
        qdot: DVector::zeros(n),
        scale: 0.0,
        saturated: vec![false; n],
        sigma_min: 0.0,
        damping: 0.0,
        rejected,
    };
    if jacobian
        .iter()
        .chain(twist.iter())
        .chain(q.iter())
        .any(|v| !v.is_finite())
        || q.len() != n
        || limits.len() != n
    {
        return zero(true);
    }
    let sigma_min = smallest_singular_value(jacobian);
    let eps = settings.singular_threshold;
    let lambda2 = if sigma_min >= eps {
        0.0
    } else {
        (1.0 - (sigma_min / eps).powi(2)) * settings.max_damping.powi(2)
    };
    let dt = settings.dt.max(1e-6);

    let mut qdot = DVector::zeros(n);
    let mut saturated = vec![false; n];
    for _ in 0..=n {
        let free: Vec<usize> = (0..n).filter(|&i| !saturated[i]).collect();
        if free.is_empty() {
            break;
        }
        // Twist left for the free joints after the saturated ones.
        let mut rest = *twist;
        for i in (0..n).filter(|&i| saturated[i]) {
            rest -= jacobian.column(i) * qdot[i];
        }
        let jf = DMatrix::from_fn(6, free.len(), |r, c| jacobian[(r, free[c])]);
        let a = &jf * jf.transpose() + DMatrix::identity(6, 6) * lambda2;
        let y = match a.clone().cholesky() {
            Some(ch) => ch.solve(&DVector::from_column_slice(rest.as_slice())),
            None => a
                .svd(true, true)
                .solve(&DVector::from_column_slice(rest.as_slice()), 1e-12)
                .unwrap_or_else(|_| DVector::zeros(6)),
        };
        let sol = jf.transpose() * y;
        let mut newly = false;
        for (k, &i) in free.iter().enumerate() {
            qdot[i] = sol[k];
            let (lo, hi) = position_velocity_bounds(q[i], &limits[i], dt);
            if qdot[i] < lo || qdot[i] > hi {
                qdot[i] = qdot[i].clamp(lo, hi);
                saturated[i] = true;
                newly = true;
            }
        }
        if !newly {
            break;
        }
    }
    let mut scale: f64 = 1.0;
    for (v, l) in qdot.iter().zip(limits) {
        if v.abs() > l.velocity {
            scale = scale.min(l.velocity / v.abs());
        }
    }
    qdot *= scale;
    if qdot.iter().any(|v| !v.is_finite()) {
        return zero(true);
    }
    IkStep {
        qdot,
        scale,
        saturated,
        sigma_min,
        damping: lambda2.sqrt(),
        rejected: false,
    }
}

/// The velocity range that keeps a joint within its position limits after `dt`. A joint already
/// outside its range gets a range that only moves it back. Velocity limits are not applied here
/// but by uniform scaling afterwards, which keeps the direction of motion.
fn position_velocity_bounds(q: f64, l: &JointLimits, dt: f64) -> (f64, f64) {
    ((l.lower - q) / dt, (l.upper - q) / dt)
}

/// Joint velocities by the plain Moore–Penrose pseudoinverse, without damping or limits: the
/// textbook baseline that DLS is compared against near singularities.
pub fn pinv_step(jacobian: &Matrix6xX<f64>, twist: &Vector6<f64>) -> DVector<f64> {
    let j = DMatrix::from_column_slice(6, jacobian.ncols(), jacobian.as_slice());
    j.svd(true, true)
        .solve(&DVector::from_column_slice(twist.as_slice()), 1e-300)
        .unwrap_or_else(|_| DVector::zeros(jacobian.ncols()))
}

/// Smallest of the first min(6, n) singular values.
pub fn smallest_singular_value(jacobian: &Matrix6xX<f64>) -> f64 {
    let j = DMatrix::from_column_slice(6, jacobian.ncols(), jacobian.as_slice());
    j.singular_values()
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min)
}

/// Joint positions that put `link` at `target` (world frame, robot root at `base`), found by
/// iterating [`dls_step`] from `q_start` with only the joints in `arm` moving, within their
/// position limits. Errors, with the remaining error, when it does not reach 0.1 mm and
/// 0.01° (an unreachable pose, or a start that converges to a limit).
pub fn solve_pose(
    model: &RobotModel,
    base: &Isometry3<f64>,
    link: LinkId,
    arm: &[usize],
    q_start: &DVector<f64>,
    target: &Isometry3<f64>,
) -> crate::Result<DVector<f64>> {
    let limits = model.dof_limits();
    if q_start.len() != limits.len() || arm.iter().any(|&i| i >= limits.len()) {
        return Err(crate::Error::Ik {
            message: format!(
                "{} joints given, arm indices must be below {}",
                q_start.len(),
                limits.len()
            ),
        });
    }
    let lim_arm: Vec<JointLimits> = arm.iter().map(|&i| limits[i]).collect();
    // One unit of time per iteration: the twist is the whole remaining error (a Newton step,
    // damped near singularities, stopped at the limits). Velocity limits do not apply here.
    let settings = DlsSettings {
        dt: 1.0,
        ..DlsSettings::default()
    };
    let unlimited: Vec<JointLimits> = lim_arm
        .iter()
        .map(|l| JointLimits {
            velocity: f64::INFINITY,
            ..*l
        })
        .collect();
    let mut q = q_start.clone();
    let mut err = Vector6::zeros();
    for _ in 0..500 {
        let poses = model.forward_kinematics(base, q.as_slice());
        err = pose_difference(&poses[link], target);
        if err.fixed_rows::<3>(0).norm() < 1e-4 && err.fixed_rows::<3>(3).norm() < 1.7e-4 {
            return Ok(q);
        }
        let j_full = model.jacobian_from_poses(&poses, link, &Vector3::zeros(), Frame::World);
        let j = Matrix6xX::from_fn(arm.len(), |r, c| j_full[(r, arm[c])]);
        let q_arm: Vec<f64> = arm.iter().map(|&i| q[i]).collect();
        let step = dls_step(&j, &(err * 0.5), &q_arm, &unlimited, &settings);
        if step.rejected {
            break;
        }
        for (k, &i) in arm.iter().enumerate() {
            q[i] = lim_arm[k].clamp_position(q[i] + step.qdot[k]);
        }
    }
    Err(crate::Error::Ik {
        message: format!(
            "the pose is not reached: {:.1} mm and {:.2} deg left",
            err.fixed_rows::<3>(0).norm() * 1e3,
            err.fixed_rows::<3>(3).norm().to_degrees()
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::kinematics::{Frame, pose_difference};
    use nalgebra::{Isometry3, Vector3};

    fn sawyer() -> crate::robot::RobotModel {
        crate::robot::kinematics::tests::sawyer()
    }

    #[test]
    fn solves_a_side_grasp_and_refuses_an_unreachable_pose() {
        let r = sawyer();
        let tip = r.link_id("right_gripper_tip").unwrap();
        let base = Isometry3::translation(0.0, 0.0, 0.75);
        let q0 = DVector::from_row_slice(&[0.0, -1.18, 0.0, 2.18, 0.0, 0.57, 3.3161, 0.02, 0.02]);
        let arm: Vec<usize> = (0..7).collect();
        // Tool z horizontal toward +x, fingers closing along y, at a bottle on the desk.
        let rot = nalgebra::UnitQuaternion::from_matrix(&nalgebra::Matrix3::new(
            0.0, 0.0, 1.0, 0.0, 1.0, 0.0, -1.0, 0.0, 0.0,
        ));
        let target = Isometry3::from_parts(nalgebra::Translation3::new(0.62, -0.16, 0.84), rot);
        let q = solve_pose(&r, &base, tip, &arm, &q0, &target).expect("reachable");
        let got = r.forward_kinematics(&base, q.as_slice())[tip];
        assert!((got.translation.vector - target.translation.vector).norm() < 2e-4);
        assert!(got.rotation.angle_to(&target.rotation) < 1e-3);
        let limits = r.dof_limits();
        assert!(
            q.iter()
                .zip(&limits)
                .all(|(v, l)| *v >= l.lower && *v <= l.upper)
        );
        assert_eq!((q[7], q[8]), (0.02, 0.02), "only the arm moves");
        let far = Isometry3::from_parts(nalgebra::Translation3::new(2.5, 0.0, 0.8), rot);
        let err = solve_pose(&r, &base, tip, &arm, &q0, &far).expect_err("out of reach");
        assert!(err.to_string().contains("not reached"), "{err}");
    }

    #[test]
    fn tracks_a_reachable_pose_within_limits() {
        let r = sawyer();
        let tip = r.link_id("right_hand").unwrap();
        let base = Isometry3::identity();
        let limits = r.dof_limits();
        let target_q = [0.4, -0.6, 0.1, 1.2, -0.3, 0.8, 0.5, 0.0, 0.0];
        let target = r.forward_kinematics(&base, &target_q)[tip];
        let mut q = vec![0.0, -0.3, 0.0, 0.9, 0.0, 0.6, 0.0, 0.0, 0.0];
        let settings = DlsSettings {
            dt: 0.01,
            ..Default::default()
        };
        for _ in 0..3000 {
            let pose = r.forward_kinematics(&base, &q)[tip];
            let err = pose_difference(&pose, &target);
            let jac = r.jacobian(&base, &q, tip, &Vector3::zeros(), Frame::World);
            let step = dls_step(&jac, &(err * 5.0), &q, &limits, &settings);
            for (i, qi) in q.iter_mut().enumerate() {
                assert!(step.qdot[i].abs() <= limits[i].velocity + 1e-9);
                *qi += step.qdot[i] * settings.dt;
                assert!(*qi >= limits[i].lower - 1e-9 && *qi <= limits[i].upper + 1e-9);
            }
        }
        let pose = r.forward_kinematics(&base, &q)[tip];
        let err = pose_difference(&pose, &target);
        assert!(err.fixed_rows::<3>(0).norm() < 1e-4, "{err}");
        assert!(err.fixed_rows::<3>(3).norm() < 1e-3, "{err}");
    }

    #[test]
    fn stays_bounded_at_a_singularity_where_the_pseudoinverse_blows_up() {
        let r = sawyer();
        let tip = r.link_id("right_hand").unwrap();
        let base = Isometry3::identity();
        let limits = r.dof_limits();
        // Near-straight elbow and aligned wrist: a near-singular configuration.
        let q = [0.0, 0.0, 0.0, 1e-7, 0.0, 1e-7, 0.0, 0.0, 0.0];
        let jac = r.jacobian(&base, &q, tip, &Vector3::zeros(), Frame::World);
        let sigma = smallest_singular_value(&jac);
        assert!(sigma < 1e-3, "not singular: {sigma}");
        // A twist partly along the lost direction.
        let svd = DMatrix::from_column_slice(6, jac.ncols(), jac.as_slice()).svd(true, false);
        let (k, _) =
            svd.singular_values
                .iter()
                .enumerate()
                .fold(
                    (0, f64::INFINITY),
                    |b, (i, &s)| if s < b.1 { (i, s) } else { b },
                );
        let u = svd.u.as_ref().map(|u| u.column(k).into_owned());
        let dir = Vector6::from_iterator(u.unwrap_or_else(|| DVector::zeros(6)).iter().copied());
        let twist = dir * 0.05 + Vector6::new(0.02, 0.0, 0.0, 0.0, 0.0, 0.0);
        let plain = pinv_step(&jac, &twist);
        assert!(
            plain.amax() > 100.0,
            "pseudoinverse stayed small: {}",
            plain.amax()
        );
        let step = dls_step(&jac, &twist, &q, &limits, &DlsSettings::default());
        assert!(!step.rejected);
        for (v, l) in step.qdot.iter().zip(&limits) {
            assert!(v.abs() <= l.velocity + 1e-12);
        }
        assert!(step.damping > 0.0);
    }

    #[test]
    fn rejects_nan_and_stops_at_position_limits() {
        let mut j = Matrix6xX::zeros(1);
        j[(0, 0)] = 1.0;
        let lim = [JointLimits {
            lower: -1.0,
            upper: 1.0,
            velocity: 2.0,
            effort: 1.0,
        }];
        let s = DlsSettings {
            dt: 0.1,
            ..Default::default()
        };
        let nan = dls_step(
            &j,
            &Vector6::new(f64::NAN, 0.0, 0.0, 0.0, 0.0, 0.0),
            &[0.0],
            &lim,
            &s,
        );
        assert!(nan.rejected && nan.qdot[0] == 0.0);
        // 0.05 from the upper limit, asked to go at 1.5: stops on the limit after dt.
        let step = dls_step(
            &j,
            &Vector6::new(1.5, 0.0, 0.0, 0.0, 0.0, 0.0),
            &[0.95],
            &lim,
            &s,
        );
        assert!(step.saturated[0]);
        assert!((step.qdot[0] - 0.5).abs() < 1e-12);
        // Outside the range: only moving back is allowed.
        let back = dls_step(
            &j,
            &Vector6::new(1.0, 0.0, 0.0, 0.0, 0.0, 0.0),
            &[1.2],
            &lim,
            &s,
        );
        assert!(back.qdot[0] <= 0.0);
        // Velocity limit scales uniformly.
        let fast = dls_step(
            &j,
            &Vector6::new(-5.0, 0.0, 0.0, 0.0, 0.0, 0.0),
            &[0.0],
            &lim,
            &DlsSettings { dt: 1e-3, ..s },
        );
        assert!((fast.qdot[0] + 2.0).abs() < 1e-12 && fast.scale < 1.0);
    }
}
