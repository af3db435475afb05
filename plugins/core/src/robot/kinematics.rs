//! Forward kinematics of every link and geometric Jacobians.
//!
//! Twists are `[v; ω]`: linear velocity first, then angular velocity. Joint vectors follow the
//! robot's depth-first movable-joint order ([`RobotModel::dofs`]); a shorter slice reads as
//! zeros for the missing joints.

use nalgebra::{Isometry3, Matrix6xX, Point3, Vector3};

use crate::robot::{JointKind, LinkId, RobotModel};

/// The frame a Jacobian's rows are expressed in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Frame {
    /// The robot's root frame.
    #[default]
    World,
    /// The link's own frame (rows rotated into it; the reference point stays the link point).
    Local,
}

impl RobotModel {
    /// World pose of every link (index = [`LinkId`]), with the root link at `base`.
    ///
    /// ```
    /// # use avatarm_core::robot::{RobotModel, PackagePath};
    /// # use nalgebra::Isometry3;
    /// let urdf = r#"<robot name="r"><link name="a"/><link name="b"/>
    ///   <joint name="j" type="prismatic"><parent link="a"/><child link="b"/><axis xyz="1 0 0"/>
    ///   <limit lower="0" upper="1" velocity="1" effort="1"/></joint></robot>"#;
    /// let robot = RobotModel::from_urdf_str(urdf, None, &PackagePath::default()).unwrap();
    /// let poses = robot.forward_kinematics(&Isometry3::identity(), &[0.25]);
    /// assert!((poses[1].translation.x - 0.25).abs() < 1e-12);
    /// ```
    pub fn forward_kinematics(&self, base: &Isometry3<f64>, q: &[f64]) -> Vec<Isometry3<f64>> {
        let mut poses = vec![*base; self.links.len()];
        // Joints are depth-first, so a joint's parent pose is always computed before it.
        for joint in &self.joints {
            poses[joint.child] = poses[joint.parent] * joint.transform(joint.position(q));
        }
        poses
    }

    /// Geometric Jacobian (6 × dof) of a point fixed on `link` (given in the link frame).
    ///
    /// Column `i` is the twist `[v; ω]` of that point for a unit velocity of movable joint `i`;
    /// joints that are not ancestors of `link` give zero columns. A mimic joint on the chain adds
    /// its own twist times its gain to its leader's column (chain rule).
    pub fn jacobian(
        &self,
        base: &Isometry3<f64>,
        q: &[f64],
        link: LinkId,
        point_in_link: &Vector3<f64>,
        frame: Frame,
    ) -> Matrix6xX<f64> {
        let poses = self.forward_kinematics(base, q);
        self.jacobian_from_poses(&poses, link, point_in_link, frame)
    }

    /// As [`RobotModel::jacobian`], reusing link poses already computed for the same `q`.
    pub fn jacobian_from_poses(
        &self,
        poses: &[Isometry3<f64>],
        link: LinkId,
        point_in_link: &Vector3<f64>,
        frame: Frame,
    ) -> Matrix6xX<f64> {
        let mut jac = Matrix6xX::zeros(self.dof());
        let p = poses[link] * Point3::from(*point_in_link);
        let mut current = link;
        while let Some(ji) = self.links[current].parent_joint {
            let joint = &self.joints[ji];
            if let Some((col, gain)) = joint.drive() {
                let joint_frame = poses[joint.parent] * joint.origin;
                let z = joint_frame.rotation * joint.axis.into_inner();
                let (v, w) = match joint.kind {
                    JointKind::Revolute | JointKind::Continuous => {
                        let o = Point3::from(joint_frame.translation.vector);
                        (z.cross(&(p - o)), z)
                    }
                    JointKind::Prismatic => (z, Vector3::zeros()),
                    JointKind::Fixed => (Vector3::zeros(), Vector3::zeros()),
                };
                let mut column = jac.fixed_view_mut::<6, 1>(0, col);
                column += nalgebra::Vector6::new(v.x, v.y, v.z, w.x, w.y, w.z) * gain;
            }
            current = joint.parent;
        }
        if frame == Frame::Local {
            let r_inv = poses[link].rotation.inverse();
            for mut c in jac.column_iter_mut() {
                let v = r_inv * Vector3::new(c[0], c[1], c[2]);
                let w = r_inv * Vector3::new(c[3], c[4], c[5]);
                c.copy_from_slice(&[v.x, v.y, v.z, w.x, w.y, w.z]);
            }
        }
        jac
    }
}

/// The 6-vector `[Δp; Δθ]` that takes pose `a` to pose `b` (rotation as a world-frame rotation
/// vector), the finite-difference counterpart of a twist.
pub fn pose_difference(a: &Isometry3<f64>, b: &Isometry3<f64>) -> nalgebra::Vector6<f64> {
    let dp = b.translation.vector - a.translation.vector;
    let dr = (b.rotation * a.rotation.inverse()).scaled_axis();
    nalgebra::Vector6::new(dp.x, dp.y, dp.z, dr.x, dr.y, dr.z)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::robot::PackagePath;
    use nalgebra::DVector;
    use proptest::prelude::*;

    /// Planar 2R arm in the x–y plane, link lengths 0.7 and 0.4.
    const PLANAR: &str = r#"<robot name="planar">
      <link name="base"/><link name="l1"/><link name="l2"/><link name="tip"/>
      <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
        <axis xyz="0 0 1"/><limit lower="-3" upper="3" velocity="1" effort="1"/></joint>
      <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
        <origin xyz="0.7 0 0"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" velocity="1" effort="1"/></joint>
      <joint name="tool" type="fixed"><parent link="l2"/><child link="tip"/><origin xyz="0.4 0 0"/></joint>
    </robot>"#;

    pub(crate) fn sawyer() -> RobotModel {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../assets/robots/sawyer_lite/sawyer_lite.urdf");
        RobotModel::from_urdf_file(&path, &PackagePath::default()).unwrap()
    }

    #[test]
    fn planar_arm_matches_closed_form() {
        let r = RobotModel::from_urdf_str(PLANAR, None, &PackagePath::default()).unwrap();
        let tip = r.link_id("tip").unwrap();
        let (l1, l2) = (0.7, 0.4);
        for &(a, b) in &[(0.0, 0.0), (0.3, -1.1), (2.0, 0.5), (-1.2, 2.9)] {
            let poses = r.forward_kinematics(&Isometry3::identity(), &[a, b]);
            let x = l1 * f64::cos(a) + l2 * f64::cos(a + b);
            let y = l1 * f64::sin(a) + l2 * f64::sin(a + b);
            let t = poses[tip].translation.vector;
            assert!((t.x - x).abs() < 1e-12 && (t.y - y).abs() < 1e-12 && t.z.abs() < 1e-12);
            let jac = r.jacobian(
                &Isometry3::identity(),
                &[a, b],
                tip,
                &Vector3::zeros(),
                Frame::World,
            );
            let expected = [
                [
                    -l1 * f64::sin(a) - l2 * f64::sin(a + b),
                    -l2 * f64::sin(a + b),
                ],
                [
                    l1 * f64::cos(a) + l2 * f64::cos(a + b),
                    l2 * f64::cos(a + b),
                ],
            ];
            for (row, exp) in expected.iter().enumerate() {
                for (col, e) in exp.iter().enumerate() {
                    assert!((jac[(row, col)] - e).abs() < 1e-12);
                }
            }
            // Angular part: both joints rotate about world z.
            assert_eq!(jac[(5, 0)], 1.0);
            assert_eq!(jac[(5, 1)], 1.0);
        }
    }

    fn finite_difference_jacobian(r: &RobotModel, q: &[f64], link: LinkId) -> Matrix6xX<f64> {
        let h = 1e-6;
        let base = Isometry3::identity();
        let mut jac = Matrix6xX::zeros(r.dof());
        for i in 0..r.dof() {
            let mut qp = q.to_vec();
            let mut qm = q.to_vec();
            qp[i] += h;
            qm[i] -= h;
            let a = r.forward_kinematics(&base, &qm)[link];
            let b = r.forward_kinematics(&base, &qp)[link];
            jac.set_column(i, &(pose_difference(&a, &b) / (2.0 * h)));
        }
        jac
    }

    #[test]
    fn sawyer_jacobian_matches_finite_differences() {
        let r = sawyer();
        let tip = r.link_id("right_hand").unwrap();
        let q = [0.3, -0.8, 0.2, 1.4, -0.5, 0.9, 1.7, 0.01, 0.015];
        let analytic = r.jacobian(
            &Isometry3::identity(),
            &q,
            tip,
            &Vector3::zeros(),
            Frame::World,
        );
        let numeric = finite_difference_jacobian(&r, &q, tip);
        assert!((analytic - numeric).abs().max() < 1e-6);
    }

    #[test]
    fn local_frame_is_the_world_jacobian_rotated() {
        let r = sawyer();
        let tip = r.tip_link();
        let q = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.0, 0.02];
        let base = Isometry3::identity();
        let world = r.jacobian(&base, &q, tip, &Vector3::zeros(), Frame::World);
        let local = r.jacobian(&base, &q, tip, &Vector3::zeros(), Frame::Local);
        let rot = r.forward_kinematics(&base, &q)[tip].rotation;
        for c in 0..r.dof() {
            let v = rot * Vector3::new(local[(0, c)], local[(1, c)], local[(2, c)]);
            let w = rot * Vector3::new(local[(3, c)], local[(4, c)], local[(5, c)]);
            assert!((v - world.fixed_view::<3, 1>(0, c)).norm() < 1e-12);
            assert!((w - world.fixed_view::<3, 1>(3, c)).norm() < 1e-12);
        }
    }

    /// A leader, a follower that mimics it (×2, +0.1) and a fixed tip, as in
    /// ../shared/cases/09-mimic-joint.
    const MIMIC: &str = r#"<robot name="mimic_pair">
      <link name="base_link"/><link name="l1"/><link name="l2"/><link name="tip"/>
      <joint name="j_leader" type="revolute"><parent link="base_link"/><child link="l1"/>
        <origin xyz="0 0 0.1"/><axis xyz="0 0 1"/><limit lower="-1.5" upper="1.5" effort="10" velocity="1"/></joint>
      <joint name="j_follower" type="revolute"><parent link="l1"/><child link="l2"/>
        <origin xyz="0.3 0 0"/><axis xyz="0 0 1"/><limit lower="-3.2" upper="3.2" effort="10" velocity="2"/>
        <mimic joint="j_leader" multiplier="2.0" offset="0.1"/></joint>
      <joint name="tip_joint" type="fixed"><parent link="l2"/><child link="tip"/><origin xyz="0.2 0 0"/></joint>
    </robot>"#;

    #[test]
    fn a_mimic_joint_follows_its_leader_in_fk_and_the_jacobian() {
        let r = RobotModel::from_urdf_str(MIMIC, None, &PackagePath::default()).unwrap();
        assert_eq!(r.dof_names(), ["j_leader"]);
        let (l2, tip) = (r.link_id("l2").unwrap(), r.link_id("tip").unwrap());
        for a in [0.3, -0.7, 1.2] {
            // Hand-computed chain: l2 at 0.3·(cos a, sin a), the follower at 2a + 0.1.
            let b = 2.0 * a + 0.1;
            let poses = r.forward_kinematics(&Isometry3::identity(), &[a]);
            let p2 = Vector3::new(0.3 * a.cos(), 0.3 * a.sin(), 0.1);
            let pt = p2 + Vector3::new(0.2 * (a + b).cos(), 0.2 * (a + b).sin(), 0.0);
            assert!((poses[l2].translation.vector - p2).norm() < 1e-12);
            assert!((poses[tip].translation.vector - pt).norm() < 1e-12);
            let follower = r.joints.iter().find(|j| j.name == "j_follower").unwrap();
            assert!((follower.position(&[a]) - b).abs() < 1e-15);
            let jac = r.jacobian(
                &Isometry3::identity(),
                &[a],
                tip,
                &Vector3::zeros(),
                Frame::World,
            );
            let numeric = finite_difference_jacobian(&r, &[a], tip);
            assert!((&jac - &numeric).abs().max() < 1e-7);
            // ∂(tip angle)/∂a = 1 + 2.
            assert!((numeric[(5, 0)] - 3.0).abs() < 1e-7);
        }
        // The case's numbers at a = 0.3.
        let poses = r.forward_kinematics(&Isometry3::identity(), &[0.3]);
        let want = Vector3::new(0.394661407911, 0.256950258960, 0.1);
        assert!((poses[tip].translation.vector - want).norm() < 1e-9);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// J(q)·q̇ equals the finite difference of FK along q̇, for random q and q̇.
        #[test]
        fn jacobian_times_qdot_is_fk_derivative(
            q in prop::collection::vec(-2.5f64..2.5, 9),
            qdot in prop::collection::vec(-1.0f64..1.0, 9),
            px in -0.1f64..0.1,
        ) {
            let r = sawyer();
            let tip = r.tip_link();
            let point = Vector3::new(px, 0.02, 0.05);
            let base = Isometry3::translation(0.1, -0.2, 0.3);
            let jac = r.jacobian(&base, &q, tip, &point, Frame::World);
            let twist = &jac * DVector::from_column_slice(&qdot);
            let h = 1e-6;
            let step = |s: f64| {
                let qs: Vec<f64> = q.iter().zip(&qdot).map(|(a, b)| a + s * b).collect();
                let pose = r.forward_kinematics(&base, &qs)[tip];
                (pose, pose * Point3::from(point))
            };
            let (a, pa) = step(-h);
            let (b, pb) = step(h);
            let v = (pb - pa) / (2.0 * h);
            let w = pose_difference(&a, &b).fixed_rows::<3>(3) / (2.0 * h);
            prop_assert!((twist.fixed_rows::<3>(0) - v).norm() < 1e-6);
            prop_assert!((twist.fixed_rows::<3>(3) - w).norm() < 1e-6);
        }
    }
}
