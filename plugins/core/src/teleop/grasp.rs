//! Grasp theory for the motion mapping (Prattichizzo & Trinkle, *Grasping*, Springer Handbook
//! of Robotics, ch. 28), in one convention throughout:
//!
//! - Object twist `ν = [v; ω]` (6) and wrench `w = [f; τ]` (6), both in the world frame, the
//!   moment and the linear velocity taken at the object's reference point `o`.
//! - Each of the `n` contacts transmits `d` components: `d = 3` for a hard finger (point contact
//!   with friction: a force) or `d = 6` for a complete (glued) contact (force and moment). The
//!   contact forces stack into `λ ∈ ℝ^{dn}`, world frame.
//! - The grasp matrix `G ∈ ℝ^{6×dn}` maps contact forces to the object wrench, `w = G λ`, with
//!   block `G_i = [I 0; S(p_i − o) I]` (the first `d` columns for a hard finger). By the
//!   kinetostatic duality `Gᵀ ∈ ℝ^{dn×6}` maps the object twist to the contact twists,
//!   `ν_c = Gᵀ ν`.
//! - Internal forces are the part of `λ` in the null space of `G`: `λ_int = (I − G⁺G) λ`, with
//!   `G⁺` the Moore–Penrose pseudoinverse (so the projector is right also when `G` loses rank:
//!   one contact, or collinear contacts). The paper writes the projector as `(I − GᵀG)†`, which
//!   only type-checks if its `G` is our `Gᵀ`; see `docs/grasp.md`.
//! - The object twist from contact twists is the least-squares inverse of the duality,
//!   `ν = (Gᵀ)⁺ ν_c`; for contacts that move rigidly with the object it recovers `ν` exactly
//!   whenever `Gᵀ` has full column rank.

use nalgebra::{DMatrix, DVector, Matrix3, Vector3, Vector6};

/// How much a contact transmits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ContactModel {
    /// A force only (3 components): fingertip on an object, what a physics engine reports.
    HardFinger,
    /// Force and moment (6 components), as the paper's `6n` blocks.
    Complete,
}

impl ContactModel {
    /// Components per contact.
    pub fn dim(self) -> usize {
        match self {
            Self::HardFinger => 3,
            Self::Complete => 6,
        }
    }
}

/// One contact on the object.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Contact {
    /// Contact point (world frame, m).
    pub point: Vector3<f64>,
    /// Unit normal pointing into the object (world frame).
    pub normal: Vector3<f64>,
    /// Force the hand applies to the object at the point (world frame, N).
    pub force: Vector3<f64>,
    /// Moment the hand applies about the point (world frame, N·m); used by
    /// [`ContactModel::Complete`] only.
    pub moment: Vector3<f64>,
}

/// Skew-symmetric matrix of `a`: `S(a) b = a × b`.
pub fn skew(a: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -a.z, a.y, a.z, 0.0, -a.x, -a.y, a.x, 0.0)
}

/// The grasp matrix `G` (6 × d·n) for contacts at `points` on an object with reference point
/// `origin`.
pub fn grasp_matrix(
    origin: &Vector3<f64>,
    points: &[Vector3<f64>],
    model: ContactModel,
) -> DMatrix<f64> {
    let d = model.dim();
    let mut g = DMatrix::zeros(6, d * points.len());
    for (i, p) in points.iter().enumerate() {
        let c = i * d;
        g.view_mut((0, c), (3, 3)).copy_from(&Matrix3::identity());
        g.view_mut((3, c), (3, 3)).copy_from(&skew(&(p - origin)));
        if d == 6 {
            g.view_mut((3, c + 3), (3, 3))
                .copy_from(&Matrix3::identity());
        }
    }
    g
}

/// Singular values below `RANK_TOL · σ_max` count as zero: a grasp that is rank-deficient in
/// exact arithmetic (two contacts, collinear contacts) keeps a "zero" singular value of
/// rounding size, which must not be inverted.
pub const RANK_TOL: f64 = 1e-7;

/// Moore–Penrose pseudoinverse with singular values below `RANK_TOL · σ_max` treated as zero.
/// `None` only for non-finite input.
///
/// Computed from the symmetric eigendecomposition of the smaller Gram matrix (`A⁺ = Aᵀ(AAᵀ)⁺`
/// for wide `A`, `(AᵀA)⁺Aᵀ` for tall): nalgebra's general SVD left residuals of 1e-5 on
/// rank-deficient grasp matrices with clustered singular values (found by the property test),
/// the symmetric solver does not.
pub fn pinv(m: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    pinv_rank(m).map(|(p, _)| p)
}

/// Rank of `m` at the same tolerance as [`pinv`].
pub fn rank(m: &DMatrix<f64>) -> usize {
    pinv_rank(m).map_or(0, |(_, r)| r)
}

/// [`pinv`] and [`rank`] from one decomposition.
fn pinv_rank(m: &DMatrix<f64>) -> Option<(DMatrix<f64>, usize)> {
    if m.iter().any(|v| !v.is_finite()) {
        return None;
    }
    if m.is_empty() {
        return Some((DMatrix::zeros(m.ncols(), m.nrows()), 0));
    }
    let wide = m.nrows() <= m.ncols();
    let gram = if wide {
        m * m.transpose()
    } else {
        m.transpose() * m
    };
    let eig = gram.symmetric_eigen();
    let max = eig.eigenvalues.iter().copied().fold(0.0, f64::max);
    let tol = (max * RANK_TOL * RANK_TOL).max(f64::MIN_POSITIVE);
    let rank = eig.eigenvalues.iter().filter(|&&mu| mu > tol).count();
    let inv = DMatrix::from_diagonal(
        &eig.eigenvalues
            .map(|mu| if mu > tol { 1.0 / mu } else { 0.0 }),
    );
    let gram_pinv = &eig.eigenvectors * inv * eig.eigenvectors.transpose();
    let p = if wide {
        m.transpose() * gram_pinv
    } else {
        gram_pinv * m.transpose()
    };
    Some((p, rank))
}

/// Stacked contact forces `λ` (d·n) in the contact model's layout.
pub fn stack_forces(contacts: &[Contact], model: ContactModel) -> DVector<f64> {
    let d = model.dim();
    let mut l = DVector::zeros(d * contacts.len());
    for (i, c) in contacts.iter().enumerate() {
        l.rows_mut(i * d, 3).copy_from(&c.force);
        if d == 6 {
            l.rows_mut(i * d + 3, 3).copy_from(&c.moment);
        }
    }
    l
}

/// What the grasp analysis gives for one set of contacts.
#[derive(Debug, Clone, PartialEq)]
pub struct GraspAnalysis {
    /// The grasp matrix.
    pub g: DMatrix<f64>,
    /// Its pseudoinverse `G⁺` (so `(Gᵀ)⁺ = (G⁺)ᵀ` needs no second decomposition).
    pub g_pinv: DMatrix<f64>,
    /// Its rank (6 for a grasp that can resist any wrench's direction).
    pub rank: usize,
    /// Net wrench on the object, `G λ`.
    pub wrench: Vector6<f64>,
    /// Internal (squeezing) contact forces, `(I − G⁺G) λ`.
    pub internal: DVector<f64>,
    /// Squeezing force σ: the internal forces' components along the inward normals, averaged
    /// over the contacts (N; positive squeezes).
    pub squeeze: f64,
}

fn finite3(v: &Vector3<f64>) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// Grasp matrix, net wrench, internal forces and squeezing force for `contacts` on an object
/// with reference point `origin`.
pub fn analyse(
    origin: &Vector3<f64>,
    contacts: &[Contact],
    model: ContactModel,
) -> crate::Result<GraspAnalysis> {
    if contacts.is_empty() {
        return Err(crate::Error::NoContacts);
    }
    if !finite3(origin) {
        return Err(crate::Error::grasp_not_finite("object origin"));
    }
    for c in contacts {
        if !(finite3(&c.point) && finite3(&c.normal) && finite3(&c.force) && finite3(&c.moment)) {
            return Err(crate::Error::grasp_not_finite("contact"));
        }
    }
    let points: Vec<Vector3<f64>> = contacts.iter().map(|c| c.point).collect();
    let g = grasp_matrix(origin, &points, model);
    let lambda = stack_forces(contacts, model);
    let (g_pinv, rank) = pinv_rank(&g).ok_or(crate::Error::grasp_not_finite("grasp matrix"))?;
    let internal = &lambda - &g_pinv * (&g * &lambda);
    let w = &g * &lambda;
    let d = model.dim();
    let squeeze = contacts
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let n = c.normal.try_normalize(1e-12).unwrap_or_else(Vector3::zeros);
            n.dot(&internal.fixed_rows::<3>(i * d).into_owned())
        })
        .sum::<f64>()
        / contacts.len() as f64;
    Ok(GraspAnalysis {
        rank,
        g_pinv,
        wrench: Vector6::from_iterator(w.iter().copied()),
        internal,
        g,
        squeeze,
    })
}

/// Contact twists of contacts moving rigidly with the object: `Gᵀ ν`.
pub fn contact_twists(g: &DMatrix<f64>, twist: &Vector6<f64>) -> DVector<f64> {
    g.transpose() * DVector::from_iterator(6, twist.iter().copied())
}

/// The object twist that best explains the contact twists, `(Gᵀ)⁺ ν_c` (least squares; exact
/// for a rigid motion when `Gᵀ` has full column rank).
pub fn object_twist(
    g: &DMatrix<f64>,
    contact_twists: &DVector<f64>,
) -> crate::Result<Vector6<f64>> {
    let g_pinv = pinv(g).ok_or(crate::Error::grasp_not_finite("grasp matrix"))?;
    object_twist_from_pinv(&g_pinv, contact_twists)
}

/// As [`object_twist`], with `G⁺` already known (e.g. [`GraspAnalysis::g_pinv`]):
/// `(Gᵀ)⁺ = (G⁺)ᵀ`.
pub fn object_twist_from_pinv(
    g_pinv: &DMatrix<f64>,
    contact_twists: &DVector<f64>,
) -> crate::Result<Vector6<f64>> {
    if contact_twists.len() != g_pinv.nrows() {
        return Err(crate::Error::GraspSize {
            what: "contact twists",
            expected: g_pinv.nrows(),
            got: contact_twists.len(),
        });
    }
    if contact_twists.iter().any(|v| !v.is_finite()) {
        return Err(crate::Error::grasp_not_finite("contact twists"));
    }
    let v = g_pinv.transpose() * contact_twists;
    Ok(Vector6::from_iterator(v.iter().copied()))
}

/// Linear velocity of the point `p` of a body moving with twist `ν` taken at `o`:
/// `v + ω × (p − o)`; the angular part is unchanged.
pub fn transport_twist(
    twist: &Vector6<f64>,
    from: &Vector3<f64>,
    to: &Vector3<f64>,
) -> Vector6<f64> {
    let v = twist.fixed_rows::<3>(0).into_owned();
    let w = twist.fixed_rows::<3>(3).into_owned();
    let v2 = v + w.cross(&(to - from));
    Vector6::new(v2.x, v2.y, v2.z, w.x, w.y, w.z)
}

/// Joint torques that make the robot apply `wrench` at the point its Jacobian `jacobian` (6 ×
/// dof, same point and frame) describes: `τ = Jᵀ w`.
pub fn joint_torques(jacobian: &nalgebra::Matrix6xX<f64>, wrench: &Vector6<f64>) -> DVector<f64> {
    jacobian.transpose() * wrench
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn v3() -> impl Strategy<Value = Vector3<f64>> {
        (-0.2..0.2f64, -0.2..0.2f64, -0.2..0.2f64).prop_map(|(x, y, z)| Vector3::new(x, y, z))
    }

    fn contact(point: Vector3<f64>, force: Vector3<f64>) -> Contact {
        Contact {
            point,
            normal: -point.try_normalize(1e-12).unwrap_or(Vector3::x()),
            force,
            moment: Vector3::zeros(),
        }
    }

    proptest! {
        /// Internal forces exert no net wrench, whatever the contacts (also rank-deficient).
        #[test]
        fn internal_forces_exert_no_net_wrench(
            pts in prop::collection::vec((v3(), v3()), 1..6),
            complete in any::<bool>(),
        ) {
            let model = if complete { ContactModel::Complete } else { ContactModel::HardFinger };
            let contacts: Vec<Contact> = pts.iter().map(|(p, f)| Contact {
                moment: f * 0.1,
                ..contact(*p, *f * 10.0)
            }).collect();
            let a = analyse(&Vector3::zeros(), &contacts, model).expect("finite");
            // Zero up to rounding: near-collinear contacts make G badly conditioned, so the
            // bound scales with the forces (a wrong projector leaves residuals of their order).
            let lambda = stack_forces(&contacts, model);
            let tol = 1e-7 * (1.0 + lambda.norm());
            let net = &a.g * &a.internal;
            prop_assert!(net.norm() <= tol, "net {net}");
            // And the rest of λ carries the whole wrench.
            let external = &lambda - &a.internal;
            prop_assert!((&a.g * external - &a.g * &lambda).norm() <= tol);
        }

        /// A rigid-body twist mapped to the contacts and back is recovered (G full row rank).
        #[test]
        fn rigid_twist_round_trips(
            p in prop::collection::vec(v3(), 3..6),
            twist in prop::array::uniform6(-1.0..1.0f64),
            origin in v3(),
        ) {
            let g = grasp_matrix(&origin, &p, ContactModel::HardFinger);
            prop_assume!(rank(&g) == 6);
            let nu = Vector6::from_row_slice(&twist);
            let back = object_twist(&g, &contact_twists(&g, &nu)).expect("sizes");
            prop_assert!((back - nu).norm() < 1e-6 * (1.0 + nu.norm()), "{back} vs {nu}");
        }
    }

    #[test]
    fn contact_twists_are_point_velocities() {
        // For a rigid grasp, each contact's twist is the body's velocity at that point.
        let origin = Vector3::new(0.1, 0.0, 0.0);
        let p = [Vector3::new(0.15, 0.0, 0.0), Vector3::new(0.1, 0.05, 0.02)];
        let g = grasp_matrix(&origin, &p, ContactModel::HardFinger);
        let nu = Vector6::new(0.1, -0.2, 0.05, 0.3, -0.1, 0.7);
        let vc = contact_twists(&g, &nu);
        for (i, pi) in p.iter().enumerate() {
            let want = transport_twist(&nu, &origin, pi);
            let got = vc.fixed_rows::<3>(3 * i).into_owned();
            assert!(
                (got - want.fixed_rows::<3>(0)).norm() < 1e-12,
                "{got} vs {want}"
            );
        }
    }

    #[test]
    fn two_finger_pinch_squeezes_and_cancels() {
        // Opposite fingers pressing 5 N each along x: no net wrench, σ = 5 N.
        let contacts = [
            contact(Vector3::new(-0.03, 0.0, 0.0), Vector3::new(5.0, 0.0, 0.0)),
            contact(Vector3::new(0.03, 0.0, 0.0), Vector3::new(-5.0, 0.0, 0.0)),
        ];
        let a = analyse(&Vector3::zeros(), &contacts, ContactModel::HardFinger).expect("ok");
        assert!(a.wrench.norm() < 1e-12);
        assert!((a.squeeze - 5.0).abs() < 1e-9, "{}", a.squeeze);
        // Two points: G has rank 5 (no moment about the line through them).
        assert_eq!(a.rank, 5);
        // Adding 2 N of lift to each finger changes the wrench, not the squeeze.
        let lifted: Vec<Contact> = contacts
            .iter()
            .map(|c| Contact {
                force: c.force + Vector3::new(0.0, 0.0, 2.0),
                ..*c
            })
            .collect();
        let b = analyse(&Vector3::zeros(), &lifted, ContactModel::HardFinger).expect("ok");
        assert!((b.wrench[2] - 4.0).abs() < 1e-9);
        assert!((b.squeeze - 5.0).abs() < 1e-9);
    }

    #[test]
    fn one_contact_has_no_squeeze_and_bad_input_is_named() {
        let one = [contact(
            Vector3::new(0.03, 0.0, 0.0),
            Vector3::new(-3.0, 0.0, 1.0),
        )];
        let a = analyse(&Vector3::zeros(), &one, ContactModel::HardFinger).expect("ok");
        assert!(a.squeeze.abs() < 1e-12 && a.internal.norm() < 1e-12);
        assert_eq!(a.rank, 3);
        assert!(matches!(
            analyse(&Vector3::zeros(), &[], ContactModel::HardFinger),
            Err(crate::Error::NoContacts)
        ));
        let nan = [contact(Vector3::new(f64::NAN, 0.0, 0.0), Vector3::zeros())];
        assert!(matches!(
            analyse(&Vector3::zeros(), &nan, ContactModel::HardFinger),
            Err(crate::Error::GraspNotFinite { what: "contact" })
        ));
        let g = grasp_matrix(&Vector3::zeros(), &[Vector3::x()], ContactModel::HardFinger);
        assert!(matches!(
            object_twist(&g, &DVector::zeros(2)),
            Err(crate::Error::GraspSize {
                expected: 3,
                got: 2,
                ..
            })
        ));
    }

    #[test]
    fn collinear_contacts_are_rank_deficient_but_bounded() {
        let contacts: Vec<Contact> = (0..4)
            .map(|i| {
                let x = -0.03 + 0.02 * f64::from(i);
                contact(
                    Vector3::new(x, 0.0, 0.0),
                    Vector3::new(if x < 0.0 { 4.0 } else { -4.0 }, 0.0, 0.5),
                )
            })
            .collect();
        let a = analyse(&Vector3::zeros(), &contacts, ContactModel::HardFinger).expect("ok");
        assert_eq!(a.rank, 5);
        assert!(a.squeeze.is_finite() && a.internal.iter().all(|v| v.is_finite()));
        assert!((&a.g * &a.internal).norm() < 1e-9);
        // The twist about the common line is not observable: the least-squares twist stays
        // finite and reproduces the contact twists it can.
        let g = &a.g;
        let nu = Vector6::new(0.0, 0.1, 0.0, 0.0, 0.0, 0.2);
        let back = object_twist(g, &contact_twists(g, &nu)).expect("sizes");
        assert!((contact_twists(g, &back) - contact_twists(g, &nu)).norm() < 1e-9);
    }

    #[test]
    fn torques_are_the_jacobian_transpose() {
        let mut j = nalgebra::Matrix6xX::zeros(2);
        j[(0, 0)] = 1.0;
        j[(5, 1)] = 2.0;
        let t = joint_torques(&j, &Vector6::new(3.0, 0.0, 0.0, 0.0, 0.0, 0.5));
        assert_eq!(t.as_slice(), &[3.0, 1.0]);
    }
}
