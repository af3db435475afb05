//! The camera calibrated from the robot itself: the camera's pose (and optionally its focal
//! lengths) that makes the robot's silhouette, drawn at the recorded joints, match the observed
//! silhouettes across frames.
//!
//! The model silhouette is the robot's visual meshes (simplified to a few thousand triangles:
//! the fit needs the outline, not the last facet) posed by FK at each frame's joints, projected
//! through the candidate camera and rasterised on the CPU at a working resolution. The cost is
//! a symmetric, truncated chamfer distance between the outlines: the mean distance from each
//! model edge pixel to the nearest observed edge pixel and from each observed edge pixel to the
//! nearest model edge pixel, each capped at `truncate_px` (so a wrong part of a reference mask,
//! a missed finger, pulls with bounded force), from exact Euclidean distance transforms
//! (Felzenszwalb and Huttenlocher, *Distance Transforms of Sampled Functions*, 2012). Unlike an
//! IoU it falls smoothly as the outlines approach, far from the answer too.
//!
//! The search is Nelder-Mead (`argmin`) over a correction of the rough pose in the camera frame:
//! `camera_from_base = T(t) · exp(ω) · camera_from_base₀` with ω (rad) and t (m), and with
//! `fit_focal` a relative change of fx and fy. It starts from several corrections of the rough
//! pose (±`start_deg` about the camera's axes, ± `start_m` along its view), coarse to fine: a
//! quarter-resolution pass with a wide truncation from every start, then a half-resolution pass
//! from the best few, then a full-resolution pass (sub-pixel areas for silhouettes, a soft
//! outline for edges) from the best; for edges, from every half-resolution end within 10 % of
//! the best, the answer the lowest at full resolution (a cluttered edge map leaves near-equal
//! basins at half resolution). The spread of the starts that end in the best basin is the
//! pose's uncertainty.

use argmin::core::{CostFunction, Executor, State};
use argmin::solver::neldermead::NelderMead;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use crate::error::{Error, Result};
use crate::robot::mesh::{TriMesh, load_shape_mesh, tessellate};
use crate::robot::{GeometryKind, RobotModel};
use crate::vision::camera::Intrinsics;
use crate::vision::distortion::Distortion;

mod raster;
use raster::{BLUR_MARGIN, blur, blurred_coverage, grown_box, project, transitions};
pub use raster::{coverage, distance_transform, outline, rasterize};

/// A robot's visual geometry, loaded once and simplified to a triangle budget, to be posed at
/// each frame's joints.
#[derive(Debug, Clone)]
pub struct RobotSilhouette {
    /// Per visual: its link, its origin in the link, its vertices (link-visual frame, m) and
    /// triangles.
    parts: Vec<SilhouettePart>,
}

/// One visual of a [`RobotSilhouette`]: its link's index, its origin in the link, its vertices
/// (visual frame, m) and triangles (vertex indices).
type SilhouettePart = (usize, Isometry3<f64>, Vec<Point3<f64>>, Vec<[u32; 3]>);

impl RobotSilhouette {
    /// Loads `model`'s visual meshes (primitives tessellated) and simplifies each so that the
    /// robot has about `budget` triangles in all. Errors: a mesh that cannot be loaded, naming
    /// the link.
    pub fn new(model: &RobotModel, budget: usize) -> Result<Self> {
        let mut loaded: Vec<(usize, Isometry3<f64>, TriMesh)> = Vec::new();
        for (li, link) in model.links.iter().enumerate() {
            for g in link.geometry(GeometryKind::Visual) {
                let mesh = match load_shape_mesh(&link.name, &g.shape) {
                    Some(m) => m?,
                    None => tessellate(&g.shape, 24).unwrap_or_default(),
                };
                loaded.push((li, g.origin, mesh));
            }
        }
        let total: usize = loaded.iter().map(|(_, _, m)| m.triangle_count()).sum();
        let keep = if total > budget {
            budget as f32 / total as f32
        } else {
            1.0
        };
        let parts = loaded
            .into_iter()
            .map(|(li, origin, m)| {
                let m = m.simplified(keep);
                let vertices = m
                    .positions
                    .iter()
                    .map(|p| Point3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2])))
                    .collect();
                let triangles = m
                    .indices
                    .chunks_exact(3)
                    .map(|t| [t[0], t[1], t[2]])
                    .collect();
                (li, origin, vertices, triangles)
            })
            .collect();
        Ok(Self { parts })
    }

    /// Triangles drawn.
    pub fn triangle_count(&self) -> usize {
        self.parts.iter().map(|p| p.3.len()).sum()
    }

    /// The triangles at joints `q` (the model's q order) with the robot's root at `base`, in the
    /// frame `base` is given in.
    pub fn at(
        &self,
        model: &RobotModel,
        base: &Isometry3<f64>,
        q: &[f64],
    ) -> Vec<[Point3<f64>; 3]> {
        let poses = model.forward_kinematics(base, q);
        let mut out = Vec::with_capacity(self.triangle_count());
        for (li, origin, vertices, triangles) in &self.parts {
            let Some(link) = poses.get(*li) else {
                continue;
            };
            let pose = link * origin;
            let world: Vec<Point3<f64>> = vertices.iter().map(|v| pose * v).collect();
            out.extend(triangles.iter().filter_map(|t| {
                Some([
                    *world.get(t[0] as usize)?,
                    *world.get(t[1] as usize)?,
                    *world.get(t[2] as usize)?,
                ])
            }));
        }
        out
    }
}

/// The triangles with everything below the plane `z = z_min` (in their frame, m) cut away:
/// the part of a robot that the table it stands on hides from a camera above the table. A
/// triangle across the plane is clipped to its part above (one or two triangles).
pub fn clip_below(triangles: &[[Point3<f64>; 3]], z_min: f64) -> Vec<[Point3<f64>; 3]> {
    let mut out = Vec::with_capacity(triangles.len());
    for t in triangles {
        let above: Vec<bool> = t.iter().map(|p| p.z >= z_min).collect();
        match above.iter().filter(|&&a| a).count() {
            3 => out.push(*t),
            0 => {}
            _ => {
                // Walk the polygon's edges, keeping the vertices above and the crossings.
                let mut polygon: Vec<Point3<f64>> = Vec::with_capacity(4);
                for i in 0..3 {
                    let (a, b) = (t[i], t[(i + 1) % 3]);
                    if above[i] {
                        polygon.push(a);
                    }
                    if above[i] != above[(i + 1) % 3] {
                        let s = (z_min - a.z) / (b.z - a.z);
                        polygon.push(a + (b - a) * s);
                    }
                }
                for i in 1..polygon.len().saturating_sub(1) {
                    out.push([polygon[0], polygon[i], polygon[i + 1]]);
                }
            }
        }
    }
    out
}

/// One observed frame: the robot's triangles at the frame's joints, in the base frame, and its
/// observed silhouette (0/1 per pixel, full resolution, top row first).
#[derive(Debug, Clone)]
pub struct SilhouetteFrame {
    /// Triangles (base frame, m).
    pub triangles: Vec<[Point3<f64>; 3]>,
    /// The observed silhouette, `width × height` of the intrinsics.
    pub observed: Vec<u8>,
}

/// What each [`SilhouetteFrame::observed`] map holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Observed {
    /// The robot's silhouette (a reference mask, or the difference from an empty-room
    /// photograph): the outlines are matched both ways, then the areas at full resolution.
    #[default]
    Silhouette,
    /// The frame's image edges (0/1, e.g. Canny's): the robot's outline among the room's edges,
    /// with no silhouette at all. The cost is one-sided: the mean truncated distance from each
    /// model outline pixel to the nearest image edge, so the room's edges that the robot does
    /// not explain cost nothing (the chamfer matching of edge-based model tracking: Barrow et
    /// al., *Parametric correspondence and chamfer matching*, 1977; Borgefors, 1988). Model
    /// outline pixels missing against the rough pose count as unmatched. The last stage, at
    /// full resolution, is the squared distance (within 4 px) weighted by the gradient of the
    /// model's blurred sub-pixel coverage.
    Edges,
}

/// How the fit runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationOptions {
    /// What the frames' observed maps are.
    pub observed: Observed,
    /// Also fit fx and fy (relative changes, bounded by the search itself).
    pub fit_focal: bool,
    /// Rotation of the extra starts about each camera axis (degrees).
    pub start_deg: f64,
    /// Translation of the extra starts along the camera's view (m).
    pub start_m: f64,
    /// Nelder-Mead iterations per start and stage.
    pub max_iters: u64,
    /// The lens's distortion, applied to every projected vertex (triangle edges stay straight
    /// between them: the meshes' facets are small against its curvature).
    pub distortion: Distortion,
}

impl Default for CalibrationOptions {
    fn default() -> Self {
        Self {
            observed: Observed::Silhouette,
            fit_focal: false,
            start_deg: 8.0,
            start_m: 0.1,
            max_iters: 250,
            distortion: Distortion::None,
        }
    }
}

/// One start's end.
#[derive(Debug, Clone, PartialEq)]
pub struct StartResult {
    /// The start's correction of the rough pose: rotation (deg) and translation (m).
    pub start: ([f64; 3], [f64; 3]),
    /// The pose it ended at.
    pub camera_from_base: Isometry3<f64>,
    /// Its cost (px, the mean truncated chamfer distance at half resolution).
    pub cost_px: f64,
}

/// What the fit found.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrationResult {
    /// The camera's pose: base points into the camera's optical frame.
    pub camera_from_base: Isometry3<f64>,
    /// The intrinsics (fx, fy fitted with `fit_focal`, else as given).
    pub intrinsics: Intrinsics,
    /// The cost at the answer (px at half resolution).
    pub cost_px: f64,
    /// The cost at the rough pose (px at half resolution).
    pub rough_cost_px: f64,
    /// Every start of the fine stage: the answer (refined at full resolution) first, then the
    /// others by their cost (those refined at full resolution too, with edges, at their
    /// refined pose).
    pub starts: Vec<StartResult>,
    /// The largest rotation (deg) and translation (mm) between the answer and another start
    /// that ended within 10 % of its cost: the spread of the basin.
    pub spread_deg_mm: (f64, f64),
    /// Cost evaluations, all stages.
    pub evaluations: u64,
    /// Wall time of the coarse, fine and full-resolution stages (s).
    pub stage_seconds: [f64; 3],
    /// Cost evaluations of the coarse, fine and full-resolution stages.
    pub stage_evaluations: [u64; 3],
}

/// A frame at one working resolution: its observed outline and that outline's distance map.
struct Level {
    triangles: Vec<[Point3<f64>; 3]>,
    observed_outline: Vec<usize>,
    observed_distance: Vec<f32>,
    /// Edges: the model's outline pixels at the rough pose. A model that draws fewer (moved
    /// away, or out of the frame) has the missing ones counted as unmatched.
    rough_outline: usize,
}

/// The fit's cost at one working resolution.
struct Chamfer {
    /// At this resolution.
    correction: Correction,
    frames: Vec<Level>,
    truncate_px: f64,
    /// Edges ([`Observed::Edges`]): only the model's outline is drawn to the observed map.
    one_sided: bool,
}

/// The finest cost: the squared difference between the model's sub-pixel coverage and the
/// observed silhouette, both blurred by the same kernel (two passes of a 5-pixel box: about a
/// Gaussian of σ 1.4 px), over the observed area. Blurring makes it change smoothly as the
/// model's outline moves by a fraction of a pixel, and the observed outline's quantisation
/// averages out over its thousands of pixels; a binary raster's chamfer is flat there.
struct Area {
    correction: Correction,
    frames: Vec<AreaFrame>,
}

/// One frame of the area cost: the triangles, the observed silhouette blurred, the box
/// `[x0, y0, x1, y1)` outside which it is zero, and its area (px).
struct AreaFrame {
    triangles: Vec<[Point3<f64>; 3]>,
    observed: Vec<f32>,
    within: [usize; 4],
    area: f64,
}

/// The finest cost for image edges: the mean squared distance (px², each distance truncated at
/// `truncate_px`) from the model's soft outline to the nearest observed edge, each pixel
/// weighted by the gradient's magnitude of the model's sub-pixel coverage blurred as in
/// [`Area`]. It moves smoothly as the outline moves by a fraction of a pixel, where the binary
/// outline's chamfer is flat; squared, its minimum is where the soft outline is centred on the
/// edges, not anywhere within its width.
struct EdgeArea {
    correction: Correction,
    frames: Vec<EdgeFrame>,
    truncate_px: f32,
}

/// One frame of the soft edge cost: the triangles, and the truncated distance (px) from each
/// pixel to the nearest observed edge.
struct EdgeFrame {
    triangles: Vec<[Point3<f64>; 3]>,
    distance: Vec<f32>,
}

impl Area {
    fn new(frames: &[SilhouetteFrame], correction: Correction) -> Self {
        let (w, h) = correction.size();
        Self {
            correction,
            frames: frames
                .iter()
                .map(|f| {
                    let area = f.observed.iter().filter(|&&v| v != 0).count().max(1) as f64;
                    let mut observed: Vec<f32> = f
                        .observed
                        .iter()
                        .map(|&v| f32::from(u8::from(v != 0)))
                        .collect();
                    blur(&mut observed, w, h);
                    let set = f
                        .observed
                        .iter()
                        .enumerate()
                        .filter(|(_, v)| **v != 0)
                        .map(|(i, _)| [(i % w) as f64, (i / w) as f64]);
                    AreaFrame {
                        triangles: f.triangles.clone(),
                        observed,
                        within: grown_box(set, BLUR_MARGIN, w, h),
                        area,
                    }
                })
                .collect(),
        }
    }

    fn at(&self, p: &[f64]) -> f64 {
        let (pose, k, d) = self.correction.evaluate(p);
        let (w, h) = (k.width as usize, k.height as usize);
        let per_frame = |f: &AreaFrame| {
            let bits = coverage(&f.triangles, &pose, &k, &d);
            // Both silhouettes, blurred, are zero outside the union of their grown boxes: the
            // blur and the difference run there alone.
            let model = f
                .triangles
                .iter()
                .filter_map(|t| project(t, &pose, &k, &d))
                .flatten();
            let b = grown_box(model, BLUR_MARGIN, w, h);
            let o = f.within;
            let u = if b[0] >= b[2] || b[1] >= b[3] {
                o
            } else {
                [
                    o[0].min(b[0]),
                    o[1].min(b[1]),
                    o[2].max(b[2]),
                    o[3].max(b[3]),
                ]
            };
            let (bw, bh) = (u[2] - u[0], u[3] - u[1]);
            let m = blurred_coverage(&bits, u, w);
            let mut ssd = 0.0f64;
            for y in 0..bh {
                let observed = &f.observed[(u[1] + y) * w + u[0]..(u[1] + y) * w + u[2]];
                ssd += m[y * bw..(y + 1) * bw]
                    .iter()
                    .zip(observed)
                    .map(|(a, b)| f64::from(a - b).powi(2))
                    .sum::<f64>();
            }
            // Per cent of the observed area, so that it is of the chamfer's order.
            100.0 * ssd / f.area
        };
        mean_over_frames(&self.frames, per_frame)
    }
}

impl EdgeArea {
    fn new(frames: &[SilhouetteFrame], correction: Correction, truncate_px: f32) -> Self {
        let (w, h) = correction.size();
        Self {
            correction,
            frames: frames
                .iter()
                .map(|f| {
                    let distance = distance_transform(&f.observed, w, h)
                        .into_iter()
                        .map(|v| v.min(truncate_px))
                        .collect();
                    EdgeFrame {
                        triangles: f.triangles.clone(),
                        distance,
                    }
                })
                .collect(),
            truncate_px,
        }
    }

    fn at(&self, p: &[f64]) -> f64 {
        let (pose, k, d) = self.correction.evaluate(p);
        let (w, h) = (k.width as usize, k.height as usize);
        let far = f64::from(self.truncate_px);
        let per_frame = |EdgeFrame {
                             triangles,
                             distance,
                         }: &EdgeFrame| {
            let model = triangles
                .iter()
                .filter_map(|t| project(t, &pose, &k, &d))
                .flatten();
            let u = grown_box(model, BLUR_MARGIN, w, h);
            let (bw, bh) = (u[2].saturating_sub(u[0]), u[3].saturating_sub(u[1]));
            if bw < 3 || bh < 3 {
                return far * far;
            }
            let bits = coverage(triangles, &pose, &k, &d);
            let m = blurred_coverage(&bits, u, w);
            let (mut weight, mut sum) = (0.0f64, 0.0f64);
            for y in 1..bh - 1 {
                for x in 1..bw - 1 {
                    let i = y * bw + x;
                    let gx = m[i + 1] - m[i - 1];
                    let gy = m[i + bw] - m[i - bw];
                    let g = f64::from((gx * gx + gy * gy).sqrt());
                    weight += g;
                    sum += g * f64::from(distance[(u[1] + y) * w + u[0] + x]).powi(2);
                }
            }
            if weight < 1e-9 {
                far * far
            } else {
                sum / weight
            }
        };
        mean_over_frames(&self.frames, per_frame)
    }
}

/// The last stage's cost: areas for silhouettes, the soft outline's distance for edges.
enum FullCost {
    Area(Area),
    Edges(EdgeArea),
}

impl FullCost {
    fn at(&self, p: &[f64]) -> f64 {
        match self {
            Self::Area(a) => a.at(p),
            Self::Edges(e) => e.at(p),
        }
    }

    fn correction(&self) -> &Correction {
        match self {
            Self::Area(a) => &a.correction,
            Self::Edges(e) => &e.correction,
        }
    }
}

/// The mean of `per_frame` over the frames, on two threads (this machine's cores; the sum
/// does not depend on it).
fn mean_over_frames<F: Sync>(frames: &[F], per_frame: impl Fn(&F) -> f64 + Sync) -> f64 {
    let (first, second) = frames.split_at(frames.len().div_ceil(2));
    let total: f64 = std::thread::scope(|s| {
        let other = s.spawn(|| second.iter().map(&per_frame).sum::<f64>());
        let mine: f64 = first.iter().map(&per_frame).sum();
        mine + other.join().unwrap_or(f64::INFINITY)
    });
    total / frames.len().max(1) as f64
}

/// A stage's cost as argmin's Nelder-Mead sees it.
struct Stage<'a>(&'a dyn Fn(&[f64]) -> f64);

impl CostFunction for Stage<'_> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, p: &Self::Param) -> std::result::Result<f64, argmin::core::Error> {
        Ok((self.0)(p))
    }
}

/// What a stage's parameters mean, shared by every cost: a correction of the rough pose in
/// the camera frame, `T(t) · exp(ω) · rough` (`p[0..3]` = ω in rad, `p[3..6]` = t in m), and
/// with `fit_focal` the intrinsics `k` (at the stage's resolution) scaled by `(1 + p[6],
/// 1 + p[7])`; the lens `d` the stage draws through; and the stage's count of evaluations.
struct Correction {
    rough: Isometry3<f64>,
    k: Intrinsics,
    d: Distortion,
    fit_focal: bool,
    evaluations: std::sync::atomic::AtomicU64,
}

impl Correction {
    fn new(rough: Isometry3<f64>, k: Intrinsics, d: Distortion, fit_focal: bool) -> Self {
        Self {
            rough,
            k,
            d,
            fit_focal,
            evaluations: Default::default(),
        }
    }

    /// The same correction at `scale` of the resolution, its count at zero.
    fn scaled(&self, scale: f64) -> Self {
        Self::new(self.rough, self.k.scaled(scale), self.d, self.fit_focal)
    }

    /// The same correction, its count at zero.
    fn fresh(&self) -> Self {
        Self::new(self.rough, self.k, self.d, self.fit_focal)
    }

    /// The image size at the stage's resolution (px).
    fn size(&self) -> (usize, usize) {
        (self.k.width as usize, self.k.height as usize)
    }

    /// The pose (`camera_from_base`) and intrinsics that `p` stands for.
    fn candidate(&self, p: &[f64]) -> (Isometry3<f64>, Intrinsics) {
        let rotation = UnitQuaternion::from_scaled_axis(Vector3::new(p[0], p[1], p[2]));
        let delta = Isometry3::from_parts(Translation3::new(p[3], p[4], p[5]), rotation);
        let mut k = self.k;
        if self.fit_focal && p.len() >= 8 {
            k.fx *= 1.0 + p[6];
            k.fy *= 1.0 + p[7];
        }
        (delta * self.rough, k)
    }

    /// Counts one evaluation of the stage's cost at `p`: its pose, intrinsics and lens.
    fn evaluate(&self, p: &[f64]) -> (Isometry3<f64>, Intrinsics, Distortion) {
        self.evaluations
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let (pose, k) = self.candidate(p);
        (pose, k, self.d)
    }

    fn evaluations(&self) -> u64 {
        self.evaluations.load(std::sync::atomic::Ordering::Relaxed)
    }
}

impl Chamfer {
    /// The cost at `scale` of `full`'s resolution.
    fn new(
        frames: &[SilhouetteFrame],
        full: &Correction,
        scale: f64,
        truncate_px: f64,
        observed: Observed,
    ) -> Self {
        let correction = full.scaled(scale);
        let (small, rough, d) = (correction.k, correction.rough, correction.d);
        let (w, h) = (small.width as usize, small.height as usize);
        let (w0, h0) = (full.k.width as usize, full.k.height as usize);
        let levels = frames
            .iter()
            .map(|f| {
                let edges = match observed {
                    Observed::Silhouette => {
                        outline(&downsample(&f.observed, w0, h0, w, h, false), w, h)
                    }
                    // An edge survives the downsampling wherever it crosses a pixel.
                    Observed::Edges => downsample(&f.observed, w0, h0, w, h, true),
                };
                let rough_outline = match observed {
                    Observed::Silhouette => 0,
                    Observed::Edges => {
                        let model = rasterize(&f.triangles, &rough, &small, &d);
                        transitions(&model, w, h)
                            .iter()
                            .filter(|&&e| e != 0)
                            .count()
                    }
                };
                Level {
                    triangles: f.triangles.clone(),
                    rough_outline,
                    observed_outline: edges
                        .iter()
                        .enumerate()
                        .filter(|(_, e)| **e != 0)
                        .map(|(i, _)| i)
                        .collect(),
                    observed_distance: distance_transform(&edges, w, h),
                }
            })
            .collect();
        Self {
            correction,
            frames: levels,
            truncate_px,
            one_sided: observed == Observed::Edges,
        }
    }

    /// The mean truncated chamfer distance (px at this resolution) over the frames: both ways
    /// for silhouettes, from the model's outline alone for edges.
    fn at(&self, p: &[f64]) -> f64 {
        let (pose, k, d) = self.correction.evaluate(p);
        let (w, h) = (k.width as usize, k.height as usize);
        let tau = self.truncate_px;
        let per_frame = |f: &Level| {
            let model = rasterize(&f.triangles, &pose, &k, &d);
            // Edges: where the image shows one, on either side; a robot cut by the frame's
            // border has no image edge there.
            let edges = if self.one_sided {
                transitions(&model, w, h)
            } else {
                outline(&model, w, h)
            };
            let model_edges: Vec<usize> = edges
                .iter()
                .enumerate()
                .filter(|(_, e)| **e != 0)
                .map(|(i, _)| i)
                .collect();
            if model_edges.is_empty() || f.observed_outline.is_empty() {
                return 2.0 * tau;
            }
            let matched: f64 = model_edges
                .iter()
                .map(|&i| f64::from(f.observed_distance[i]).min(tau))
                .sum();
            if self.one_sided {
                // Fewer outline pixels than at the rough pose: the missing ones are unmatched,
                // so that a robot moved away onto a cluttered corner is no cheap answer.
                let missing = f.rough_outline.saturating_sub(model_edges.len());
                return (matched + tau * missing as f64)
                    / model_edges.len().max(f.rough_outline) as f64;
            }
            let a = matched / model_edges.len() as f64;
            let model_distance = distance_transform(&edges, w, h);
            let b: f64 = f
                .observed_outline
                .iter()
                .map(|&i| f64::from(model_distance[i]).min(tau))
                .sum::<f64>()
                / f.observed_outline.len() as f64;
            a + b
        };
        mean_over_frames(&self.frames, per_frame)
    }
}

/// A 0/1 mask of `w0 × h0` at `w × h`: a pixel is set when at least half of the source
/// pixels its footprint covers are (a box filter, so the outline does not shift by the half
/// pixel picking one source pixel would), or with `any` when one is (edges, one pixel wide);
/// upsampling repeats pixels.
fn downsample(mask: &[u8], w0: usize, h0: usize, w: usize, h: usize, any: bool) -> Vec<u8> {
    let mut out = vec![0u8; w * h];
    for y in 0..h {
        let (ya, yb) = (
            y * h0 / h,
            ((y + 1) * h0).div_ceil(h).max(y * h0 / h + 1).min(h0),
        );
        for x in 0..w {
            let (xa, xb) = (
                x * w0 / w,
                ((x + 1) * w0).div_ceil(w).max(x * w0 / w + 1).min(w0),
            );
            let (mut on, mut all) = (0usize, 0usize);
            for sy in ya..yb {
                for sx in xa..xb {
                    on += usize::from(mask[sy * w0 + sx] != 0);
                    all += 1;
                }
            }
            out[y * w + x] = u8::from(if any { on > 0 } else { 2 * on >= all.max(1) });
        }
    }
    out
}

/// The root-mean-square distance (px) between where `a` and `b` project the triangles'
/// vertices: how far two poses put the same robot apart in the image.
pub fn reprojection_rms(
    frames: &[SilhouetteFrame],
    a: &Isometry3<f64>,
    b: &Isometry3<f64>,
    k: &Intrinsics,
) -> f64 {
    let project = |pose: &Isometry3<f64>, v: &Point3<f64>| {
        let c = pose * v;
        (k.fx * c.x / c.z, k.fy * c.y / c.z)
    };
    let (mut sum, mut n) = (0.0, 0usize);
    for f in frames {
        for t in &f.triangles {
            for v in t {
                let (pa, pb) = (project(a, v), project(b, v));
                sum += (pa.0 - pb.0).powi(2) + (pa.1 - pb.1).powi(2);
                n += 1;
            }
        }
    }
    (sum / n.max(1) as f64).sqrt()
}

/// Nelder-Mead from `start` with initial steps `steps`; the best parameters and their cost.
fn search(
    cost: &dyn Fn(&[f64]) -> f64,
    start: &[f64],
    steps: &[f64],
    iters: u64,
) -> Result<(Vec<f64>, f64)> {
    let mut simplex = vec![start.to_vec()];
    for (i, s) in steps.iter().enumerate() {
        let mut v = start.to_vec();
        v[i] += s;
        simplex.push(v);
    }
    let solver = NelderMead::new(simplex)
        .with_sd_tolerance(1e-6)
        .map_err(|e| Error::BadSetting {
            what: "calibration".into(),
            message: e.to_string(),
        })?;
    let result = Executor::new(Stage(cost), solver)
        .configure(|s| s.max_iters(iters))
        .run()
        .map_err(|e| Error::BadSetting {
            what: "calibration".into(),
            message: format!("the search failed: {e}"),
        })?;
    let state = result.state();
    let best = state
        .get_best_param()
        .cloned()
        .unwrap_or_else(|| start.to_vec());
    Ok((best, state.get_best_cost()))
}

/// Fits the camera's pose (and with `fit_focal` its focal lengths) to the frames' observed
/// silhouettes (or image edges, [`Observed`]) from the rough `camera_from_base`. `progress` is
/// called after each start of each stage with (done, total). Errors: no frame, an observed mask of
/// the wrong size or empty, no triangle.
pub fn calibrate(
    frames: &[SilhouetteFrame],
    k: &Intrinsics,
    rough: &Isometry3<f64>,
    options: &CalibrationOptions,
    mut progress: impl FnMut(usize, usize),
) -> Result<CalibrationResult> {
    let bad = |message: String| Error::BadSetting {
        what: "calibration".into(),
        message,
    };
    if frames.is_empty() {
        return Err(bad("no frame to fit".into()));
    }
    let n = k.width as usize * k.height as usize;
    for (i, f) in frames.iter().enumerate() {
        let what = match options.observed {
            Observed::Silhouette => "silhouette",
            Observed::Edges => "edge map",
        };
        if f.observed.len() != n {
            return Err(bad(format!(
                "frame {i}: the observed {what} has {} pixels, the camera {}x{}",
                f.observed.len(),
                k.width,
                k.height
            )));
        }
        if !f.observed.iter().any(|&v| v != 0) {
            return Err(bad(format!("frame {i}: the observed {what} is empty")));
        }
        if f.triangles.is_empty() {
            return Err(bad(format!("frame {i}: the robot has no triangles")));
        }
    }
    let dims = if options.fit_focal { 8 } else { 6 };
    let d = options.start_deg.to_radians();
    let m = options.start_m;
    let mut starts: Vec<([f64; 3], [f64; 3])> = vec![([0.0; 3], [0.0; 3])];
    for axis in 0..3 {
        for sign in [-1.0, 1.0] {
            let mut r = [0.0; 3];
            r[axis] = sign * d;
            starts.push((r, [0.0; 3]));
        }
    }
    for sign in [-1.0, 1.0] {
        starts.push(([0.0; 3], [0.0, 0.0, sign * m]));
    }
    let param = |s: &([f64; 3], [f64; 3])| {
        let mut p = vec![0.0; dims];
        p[..3].copy_from_slice(&s.0);
        p[3..6].copy_from_slice(&s.1);
        p
    };
    let correction = Correction::new(*rough, *k, options.distortion, options.fit_focal);
    // Coarse: every start at a quarter of the resolution, outlines within 12 px there (48 px at full resolution) count.
    let coarse = Chamfer::new(frames, &correction, 0.25, 12.0, options.observed);
    let mut steps = vec![0.05, 0.05, 0.05, 0.03, 0.03, 0.06];
    if options.fit_focal {
        steps.extend([0.03, 0.03]);
    }
    let fine_count = 3.min(starts.len());
    let total = starts.len() + fine_count + 1;
    let clock = std::time::Instant::now();
    let mut coarse_ends = Vec::with_capacity(starts.len());
    for (i, s) in starts.iter().enumerate() {
        let (p, c) = search(&|p| coarse.at(p), &param(s), &steps, options.max_iters)?;
        coarse_ends.push((i, p, c));
        progress(i + 1, total);
    }
    coarse_ends.sort_by(|a, b| a.2.total_cmp(&b.2));
    let coarse_s = clock.elapsed().as_secs_f64();
    // Fine: the best few at half resolution, outlines within 10 px count.
    let fine = Chamfer::new(frames, &correction, 0.5, 10.0, options.observed);
    let fine_steps: Vec<f64> = steps.iter().map(|s| s * 0.3).collect();
    let rough_cost_px = fine.at(&vec![0.0; dims]);
    let mut ends = Vec::with_capacity(fine_count);
    for (j, (i, p, _)) in coarse_ends.iter().take(fine_count).enumerate() {
        let (p, c) = search(&|p| fine.at(p), p, &fine_steps, options.max_iters)?;
        let (pose, _) = correction.candidate(&p);
        ends.push((
            StartResult {
                start: (starts[*i].0.map(f64::to_degrees), starts[*i].1),
                camera_from_base: pose,
                cost_px: c,
            },
            p,
        ));
        progress(starts.len() + j + 1, total);
    }
    ends.sort_by(|a, b| a.0.cost_px.total_cmp(&b.0.cost_px));
    let fine_s = clock.elapsed().as_secs_f64() - coarse_s;
    // Finest, from the best, at full resolution: for a silhouette the area where the model's
    // sub-pixel coverage and the observed silhouette disagree; for edges the distance from the
    // model's soft outline to them, within 4 px.
    let full = match options.observed {
        Observed::Silhouette => FullCost::Area(Area::new(frames, correction.fresh())),
        Observed::Edges => FullCost::Edges(EdgeArea::new(frames, correction.fresh(), 4.0)),
    };
    let full_steps: Vec<f64> = fine_steps.iter().map(|s| s * 0.3).collect();
    // Edges: every fine end within 10 % of the best is refined, and the answer is the lowest
    // at full resolution (the half-resolution chamfer to a cluttered edge map cannot tell
    // such basins apart); silhouettes: the best alone.
    let contenders = match options.observed {
        Observed::Silhouette => 1,
        Observed::Edges => ends
            .iter()
            .filter(|(s, _)| s.cost_px <= ends[0].0.cost_px * 1.1 + 1e-9)
            .count()
            .max(1),
    };
    let mut chosen = (0, f64::INFINITY);
    for (j, (end, end_p)) in ends.iter_mut().enumerate().take(contenders) {
        // (Nelder-Mead returns its best, never worse than where it started on this cost.)
        let (p, c) = search(&|p| full.at(p), end_p, &full_steps, options.max_iters)?;
        let (pose, _) = correction.candidate(&p);
        end.camera_from_base = pose;
        end.cost_px = fine.at(&p);
        *end_p = p;
        if c < chosen.1 {
            chosen = (j, c);
        }
    }
    ends.swap(0, chosen.0);
    ends[1..].sort_by(|a, b| a.0.cost_px.total_cmp(&b.0.cost_px));
    progress(total, total);
    let full_s = clock.elapsed().as_secs_f64() - coarse_s - fine_s;
    let (best, best_p) = ends[0].clone();
    let (_, intrinsics) = correction.candidate(&best_p);
    let spread = ends
        .iter()
        .skip(1)
        .filter(|(s, _)| s.cost_px <= best.cost_px * 1.1 + 1e-9)
        .fold((0.0f64, 0.0f64), |(r, t), (s, _)| {
            let d = s.camera_from_base * best.camera_from_base.inverse();
            (
                r.max(d.rotation.angle().to_degrees()),
                t.max(1e3 * d.translation.vector.norm()),
            )
        });
    let stage_evaluations =
        [&coarse.correction, &fine.correction, full.correction()].map(Correction::evaluations);
    let evaluations = stage_evaluations.iter().sum();
    Ok(CalibrationResult {
        camera_from_base: best.camera_from_base,
        intrinsics,
        cost_px: best.cost_px,
        rough_cost_px,
        starts: ends.into_iter().map(|(s, _)| s).collect(),
        spread_deg_mm: spread,
        evaluations,
        stage_seconds: [coarse_s, fine_s, full_s],
        stage_evaluations,
    })
}

#[cfg(test)]
mod tests;
