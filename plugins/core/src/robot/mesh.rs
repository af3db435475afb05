//! Triangle meshes from STL, OBJ, Collada and glTF/GLB files, for the robot twin's link geometry.
//!
//! STL, OBJ and Collada are read by `mesh-loader` (openrr), glTF by `gltf`. What a file carries
//! is honoured: Collada's `<unit meter>`, `<up_axis>` (`Y_UP` and `X_UP` turned to ROS's Z-up,
//! as assimp does) and node transforms, placed here rather than by `mesh-loader` (see
//! `ColladaScene`); every instance of every geometry the visual scene instances (a file with
//! no visual scene: every geometry once); each material's diffuse colour as per-vertex colours.
//! Extensions match in any letter case (`.DAE`, `.STL`). A binary STL is recognised by its
//! size (84 bytes and 50 per triangle of the count in its header) whatever its header says: CAD
//! exporters often begin the 80-byte header with `solid`, the ASCII keyword. Any other STL is
//! ASCII when it begins with the keyword `solid`, with or without a name after it (OpenSCAD,
//! FreeCAD and meshio write a bare `solid`), and refused as neither otherwise.

use std::path::Path;

use nalgebra::{Matrix3, Matrix4, Point3, Vector3};

use crate::error::{Error, Result};

/// An indexed triangle mesh in metres (the file's units converted) times the URDF scale, in the
/// file's frame turned Z-up.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TriMesh {
    /// Vertex positions.
    pub positions: Vec<[f32; 3]>,
    /// Per-vertex unit normals, when the file has them.
    pub normals: Option<Vec<[f32; 3]>>,
    /// Triangle list, three indices per triangle, counter-clockwise seen from outside.
    pub indices: Vec<u32>,
    /// Per-vertex RGBA (0..1, the same sRGB-like convention as URDF `<color rgba>`) from the
    /// file's materials, when any material gives a colour.
    pub colors: Option<Vec<[f32; 4]>>,
}

impl TriMesh {
    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// Axis-aligned bounds `(min, max)`, or `None` for an empty mesh.
    pub fn bounds(&self) -> Option<([f32; 3], [f32; 3])> {
        let first = *self.positions.first()?;
        Some(self.positions.iter().fold((first, first), |(lo, hi), p| {
            (
                [lo[0].min(p[0]), lo[1].min(p[1]), lo[2].min(p[2])],
                [hi[0].max(p[0]), hi[1].max(p[1]), hi[2].max(p[2])],
            )
        }))
    }

    /// Appends `other`, renumbering its indices; colours and normals are kept only where both
    /// have them (missing colours become white when one side has some).
    fn append(&mut self, mut other: TriMesh) {
        let base = self.positions.len() as u32;
        let (n_self, n_other) = (self.positions.len(), other.positions.len());
        self.normals = match (self.normals.take(), other.normals.take()) {
            (Some(mut a), Some(b)) => {
                a.extend(b);
                Some(a)
            }
            (None, Some(b)) if n_self == 0 => Some(b),
            (a, None) if n_other == 0 => a,
            _ => None,
        };
        self.colors = match (self.colors.take(), other.colors.take()) {
            (None, None) => None,
            (a, b) => {
                let mut a = a.unwrap_or_else(|| vec![[1.0; 4]; n_self]);
                a.extend(b.unwrap_or_else(|| vec![[1.0; 4]; n_other]));
                Some(a)
            }
        };
        self.positions.extend(other.positions);
        self.indices.extend(other.indices.iter().map(|i| i + base));
    }
}

impl TriMesh {
    /// The mesh simplified to about `keep` (0 < `keep` ≤ 1) of its triangles, for a lighter
    /// twin: vertices that share a position are welded first (Collada and STL files repeat them
    /// per triangle), then meshoptimizer's edge-collapse simplifier (quadric error metric,
    /// Garland & Heckbert, SIGGRAPH 1997) removes triangles, pruning small disconnected parts
    /// when that is what reaches the target. Normals are dropped (the renderer recomputes
    /// them); colours follow their welded vertex. `keep` ≥ 1 (or not finite) returns a copy.
    pub fn simplified(&self, keep: f32) -> TriMesh {
        if !(keep.is_finite() && keep < 1.0) || self.indices.is_empty() {
            return self.clone();
        }
        let (count, remap) = meshopt::generate_vertex_remap(&self.positions, Some(&self.indices));
        let positions = meshopt::remap_vertex_buffer(&self.positions, count, &remap);
        let indices =
            meshopt::remap_index_buffer(Some(&self.indices), self.positions.len(), &remap);
        let colors = self
            .colors
            .as_ref()
            .map(|c| meshopt::remap_vertex_buffer(c, count, &remap));
        let target = ((self.triangle_count() as f32 * keep.max(0.0)).round() as usize).max(1) * 3;
        let indices = meshopt::simplify_decoder(
            &indices,
            &positions,
            target,
            // Relative to the mesh's extent: any error, so that the target count decides.
            1.0,
            meshopt::SimplifyOptions::Prune,
            None,
        );
        TriMesh {
            positions,
            normals: None,
            indices,
            colors,
        }
    }
}

/// The mesh formats Avatarm loads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MeshFormat {
    /// STL, ASCII or binary.
    Stl,
    /// Wavefront OBJ (with its `.mtl` colours).
    Obj,
    /// Collada (`.dae`), as most ROS descriptions' visual meshes are.
    Collada,
    /// glTF 2.0, `.gltf` or `.glb`.
    Gltf,
}

impl MeshFormat {
    /// The format of a file by its extension (any letter case), or an error naming the file and
    /// suggesting a fix.
    pub fn of(path: &Path) -> Result<Self> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or("")
            .to_ascii_lowercase();
        match ext.as_str() {
            "stl" => Ok(Self::Stl),
            "obj" => Ok(Self::Obj),
            "dae" => Ok(Self::Collada),
            "gltf" | "glb" => Ok(Self::Gltf),
            _ => Err(Error::UnsupportedMesh {
                path: path.to_owned(),
                extension: ext,
                stem: path
                    .file_stem()
                    .and_then(|s| s.to_str())
                    .unwrap_or("mesh")
                    .to_owned(),
            }),
        }
    }
}

/// A primitive shape as triangles in its own frame (URDF's: cylinders and capsules along z,
/// centred), `segments` around the round ones; `None` for a mesh file.
pub fn tessellate(shape: &crate::robot::Shape, segments: usize) -> Option<TriMesh> {
    use crate::robot::Shape;
    let n = segments.max(6);
    let mut m = TriMesh::default();
    fn push(m: &mut TriMesh, a: [f64; 3], b: [f64; 3], c: [f64; 3]) {
        let base = m.positions.len() as u32;
        for v in [a, b, c] {
            m.positions.push([v[0] as f32, v[1] as f32, v[2] as f32]);
        }
        m.indices.extend([base, base + 1, base + 2]);
    }
    // A surface of revolution about z through `profile` (radius, z) from bottom to top.
    let revolve = |m: &mut TriMesh, profile: &[(f64, f64)]| {
        for i in 0..n {
            let (a0, a1) = (
                std::f64::consts::TAU * i as f64 / n as f64,
                std::f64::consts::TAU * (i + 1) as f64 / n as f64,
            );
            for w in profile.windows(2) {
                let ((r0, z0), (r1, z1)) = (w[0], w[1]);
                let p = |r: f64, a: f64, z: f64| [r * a.cos(), r * a.sin(), z];
                push(m, p(r0, a0, z0), p(r0, a1, z0), p(r1, a1, z1));
                push(m, p(r0, a0, z0), p(r1, a1, z1), p(r1, a0, z1));
            }
        }
    };
    match shape {
        Shape::Mesh { .. } => return None,
        Shape::Box { size } => {
            let h = size / 2.0;
            let c = |x: f64, y: f64, z: f64| [x * h.x, y * h.y, z * h.z];
            let v = [
                c(-1., -1., -1.),
                c(1., -1., -1.),
                c(1., 1., -1.),
                c(-1., 1., -1.),
                c(-1., -1., 1.),
                c(1., -1., 1.),
                c(1., 1., 1.),
                c(-1., 1., 1.),
            ];
            for f in [
                [0, 3, 2, 1],
                [4, 5, 6, 7],
                [0, 1, 5, 4],
                [1, 2, 6, 5],
                [2, 3, 7, 6],
                [3, 0, 4, 7],
            ] {
                push(&mut m, v[f[0]], v[f[1]], v[f[2]]);
                push(&mut m, v[f[0]], v[f[2]], v[f[3]]);
            }
        }
        Shape::Cylinder { radius, length } => {
            let (r, h) = (*radius, length / 2.0);
            revolve(&mut m, &[(0.0, -h), (r, -h), (r, h), (0.0, h)]);
        }
        Shape::Capsule { radius, length } => {
            let (r, h) = (*radius, length / 2.0);
            let mut profile = Vec::new();
            for i in 0..=n / 2 {
                let a =
                    -std::f64::consts::FRAC_PI_2 + std::f64::consts::PI * i as f64 / (n / 2) as f64;
                let z = if a <= 0.0 { -h } else { h };
                profile.push((r * a.cos(), z + r * a.sin()));
                if i == n / 4 {
                    profile.push((r, h));
                }
            }
            revolve(&mut m, &profile);
        }
        Shape::Sphere { radius } => {
            let profile: Vec<(f64, f64)> = (0..=n / 2)
                .map(|i| {
                    let a = -std::f64::consts::FRAC_PI_2
                        + std::f64::consts::PI * i as f64 / (n / 2) as f64;
                    (radius * a.cos(), radius * a.sin())
                })
                .collect();
            revolve(&mut m, &profile);
        }
    }
    Some(m)
}

/// The mesh of a link's `<visual>` or `<collision>` shape, loaded and scaled, or `None` for a
/// primitive. Errors are [`Error::LinkMesh`], naming the link, the URI and the file: the one
/// way the twins, the bench and `avatarm robot` load a link's mesh.
pub fn load_shape_mesh(link: &str, shape: &crate::robot::Shape) -> Option<Result<TriMesh>> {
    let crate::robot::Shape::Mesh { uri, path, scale } = shape else {
        return None;
    };
    Some(load_mesh(path, scale).map_err(|source| Error::LinkMesh {
        link: link.to_owned(),
        uri: uri.clone(),
        source: Box::new(source),
    }))
}

/// Loads a mesh file and applies a per-axis scale (the URDF `<mesh scale>`).
///
/// A scale with an odd number of negative components mirrors the mesh: the triangles' winding
/// is reversed so that they still face outwards, and normals transform by the inverse scale.
///
/// # Errors
/// [`Error::Io`] when the file cannot be read, [`Error::UnsupportedMesh`] for an unknown
/// extension, [`Error::BadMesh`] (naming the file) when it cannot be parsed, has an index out of
/// range or a non-finite vertex, or the scale is 0 or not finite.
pub fn load_mesh(path: &Path, scale: &Vector3<f64>) -> Result<TriMesh> {
    let bad = |message: String| Error::BadMesh {
        path: path.to_owned(),
        message,
    };
    if scale.iter().any(|v| !v.is_finite() || *v == 0.0) {
        return Err(bad(format!(
            "scale [{} {} {}] must be finite and non-zero on every axis",
            scale.x, scale.y, scale.z
        )));
    }
    let format = MeshFormat::of(path)?;
    let mut mesh = match format {
        MeshFormat::Gltf => load_gltf(path)?,
        MeshFormat::Stl | MeshFormat::Obj | MeshFormat::Collada => {
            let bytes = std::fs::read(path).map_err(|source| Error::Io {
                path: path.to_owned(),
                source,
            })?;
            load_with_mesh_loader(path, format, &bytes).map_err(bad)?
        }
    };
    if mesh.indices.len() % 3 != 0
        || mesh
            .indices
            .iter()
            .any(|&i| i as usize >= mesh.positions.len())
    {
        return Err(bad("a triangle index is out of range".into()));
    }
    if mesh.positions.iter().flatten().any(|v| !v.is_finite()) {
        return Err(bad("a vertex position is not finite".into()));
    }
    if mesh.indices.is_empty() {
        return Err(bad("the file has no triangles".into()));
    }
    if mesh.normals.as_ref().is_some_and(|n| {
        n.len() != mesh.positions.len()
            || n.iter().any(|v| {
                let length = Vector3::from(*v).norm();
                !length.is_finite() || length < 1e-6
            })
    }) {
        // Missing, broken or zero normals (many STL exporters write 0 0 0) are recomputed
        // from the faces rather than refused.
        mesh.normals = None;
    }
    let s = scale.map(|v| v as f32);
    for p in &mut mesh.positions {
        *p = [p[0] * s.x, p[1] * s.y, p[2] * s.z];
    }
    if let Some(normals) = &mut mesh.normals {
        // Normals transform by the inverse transpose (here: inverse) scale, then renormalise.
        for n in normals.iter_mut() {
            let v = Vector3::new(n[0] / s.x, n[1] / s.y, n[2] / s.z);
            let v = v.try_normalize(1e-12).unwrap_or(Vector3::z());
            *n = [v.x, v.y, v.z];
        }
    }
    if s.x * s.y * s.z < 0.0 {
        for tri in mesh.indices.chunks_exact_mut(3) {
            tri.swap(1, 2);
        }
    }
    Ok(mesh)
}

/// STL, OBJ or Collada through `mesh-loader`, every mesh of the file merged into one with its
/// material colours. A panic inside the parser (a malformed file it does not check) is caught
/// and reported as an error, so a bad file cannot crash the app.
///
/// Collada's scene graph is placed here, not by `mesh-loader` (0.1.13 multiplies node transforms
/// in child-then-parent order and scales by `<unit>` before translating, which misplaces nested
/// or translated nodes of files not in metres): the copy it parses has the visual scene's
/// transform elements and `<unit>` blanked, and [`ColladaScene`] gives each geometry's instances.
fn load_with_mesh_loader(
    path: &Path,
    format: MeshFormat,
    bytes: &[u8],
) -> std::result::Result<TriMesh, String> {
    let collada = match format {
        MeshFormat::Collada => Some(ColladaScene::parse(bytes)?),
        _ => None,
    };
    let parse = || -> std::io::Result<mesh_loader::Scene> {
        let loader = mesh_loader::Loader::default();
        match format {
            MeshFormat::Stl => match stl_kind(bytes) {
                // A header beginning with `solid` is blanked so the parser cannot mistake the
                // file for ASCII.
                StlKind::Binary if starts_with_solid(bytes) => {
                    let mut copy = bytes.to_vec();
                    copy[..80].fill(0);
                    loader.load_stl_from_slice(&copy, path)
                }
                StlKind::Binary => loader.load_stl_from_slice(bytes, path),
                StlKind::Ascii { bare_solid: false } => loader.load_stl_from_slice(bytes, path),
                // The parser wants `solid NAME`; the name is optional in the format.
                StlKind::Ascii { bare_solid: true } => {
                    let mut named = b"solid unnamed".to_vec();
                    named.extend_from_slice(after_solid(bytes).unwrap_or_default());
                    loader.load_stl_from_slice(&named, path)
                }
                StlKind::Neither => Err(std::io::Error::new(
                    std::io::ErrorKind::InvalidData,
                    format!(
                        "neither ASCII STL (it does not begin with `solid`) nor binary STL \
                         (its {} bytes are not 84 + 50 per triangle of the count in its header)",
                        bytes.len()
                    ),
                )),
            },
            MeshFormat::Obj => loader.load_obj_from_slice(bytes, path),
            _ => loader.load_collada_from_slice(
                collada.as_ref().map_or(bytes, |c| &c.untransformed),
                path,
            ),
        }
    };
    let scene = match std::panic::catch_unwind(std::panic::AssertUnwindSafe(parse)) {
        Ok(Ok(scene)) => scene,
        Ok(Err(e)) => return Err(e.to_string()),
        Err(panic) => {
            let what = panic
                .downcast_ref::<String>()
                .map(String::as_str)
                .or_else(|| panic.downcast_ref::<&str>().copied())
                .unwrap_or("no message");
            return Err(format!("the parser failed on this file ({what})"));
        }
    };
    let mut out = TriMesh::default();
    let any_colour = scene.materials.iter().any(|m| m.color.diffuse.is_some())
        || scene.meshes.iter().any(|m| !m.colors[0].is_empty());
    for (i, m) in scene.meshes.into_iter().enumerate() {
        let n = m.vertices.len();
        let colors = any_colour.then(|| {
            if m.colors[0].len() == n {
                m.colors[0].clone()
            } else {
                let c = scene
                    .materials
                    .get(i)
                    .and_then(|mat| mat.color.diffuse)
                    .unwrap_or([1.0; 4]);
                vec![c; n]
            }
        });
        let part = TriMesh {
            normals: (m.normals.len() == n).then_some(m.normals),
            indices: m.faces.iter().flatten().copied().collect(),
            positions: m.vertices,
            colors,
        };
        match &collada {
            None => out.append(part),
            Some(c) => {
                for world in c.instances_of(&m.name) {
                    let mut placed = part.clone();
                    placed.transform(&world);
                    out.append(placed);
                }
            }
        }
    }
    Ok(out)
}

/// What `mesh-loader` is not trusted with in a Collada file: where each geometry is instanced.
struct ColladaScene {
    /// The file with the visual scene's transform elements and `<unit>` blanked out.
    untransformed: Vec<u8>,
    /// World transforms (metres, Z-up) of the instances of each geometry id.
    instances: std::collections::HashMap<String, Vec<Matrix4<f32>>>,
    /// `<up_axis>` and `<unit>`: the transform of geometry that no node instances.
    root: Matrix4<f32>,
}

impl ColladaScene {
    /// Reads `<asset>` (`<unit meter>`, `<up_axis>`) and the node tree of the visual scene that
    /// `<scene>` names (else the first): node transforms compose parent-first, and each node's
    /// `<matrix>` (row-major), `<translate>`, `<rotate>` (axis, degrees) and `<scale>` apply in
    /// document order (COLLADA 1.4.1 spec, chapter 5, "Transform elements"). `<up_axis>` Y_UP is
    /// +90° about x (y → z) and X_UP is −90° about y (x → z), as assimp's importer does.
    fn parse(bytes: &[u8]) -> std::result::Result<Self, String> {
        let text = std::str::from_utf8(bytes).map_err(|e| format!("not UTF-8 text: {e}"))?;
        let options = roxmltree::ParsingOptions {
            allow_dtd: true,
            ..Default::default()
        };
        let doc = roxmltree::Document::parse_with_options(text, options)
            .map_err(|e| format!("malformed XML: {e}"))?;
        let root = doc.root_element();
        let mut blank: Vec<std::ops::Range<usize>> = Vec::new();
        let mut unit = 1.0f32;
        let mut up = Matrix4::identity();
        if let Some(asset) = root.children().find(|n| n.has_tag_name("asset")) {
            if let Some(u) = asset.children().find(|n| n.has_tag_name("unit")) {
                let meter = u.attribute("meter").unwrap_or("1");
                unit = meter
                    .trim()
                    .parse::<f32>()
                    .ok()
                    .filter(|v| v.is_finite() && *v > 0.0)
                    .ok_or_else(|| format!("<unit meter=\"{meter}\"> is not a positive number"))?;
                blank.push(u.range());
            }
            if let Some(axis) = asset.children().find(|n| n.has_tag_name("up_axis")) {
                up = match axis.text().unwrap_or("").trim() {
                    "Z_UP" => Matrix4::identity(),
                    "Y_UP" => Matrix4::new(
                        1.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                        1.0,
                    ),
                    "X_UP" => Matrix4::new(
                        0.0, 0.0, -1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                        1.0,
                    ),
                    other => return Err(format!("<up_axis> '{other}' is not X_UP, Y_UP or Z_UP")),
                };
            }
        }
        let root_transform = up * Matrix4::new_scaling(unit);
        let scenes = root
            .children()
            .find(|n| n.has_tag_name("library_visual_scenes"));
        let wanted = root
            .children()
            .find(|n| n.has_tag_name("scene"))
            .and_then(|s| {
                s.children()
                    .find(|n| n.has_tag_name("instance_visual_scene"))
            })
            .and_then(|i| i.attribute("url"))
            .map(|u| u.trim_start_matches('#').to_owned());
        let scene = scenes.and_then(|lib| {
            let mut all = lib.children().filter(|n| n.has_tag_name("visual_scene"));
            match &wanted {
                Some(id) => all.find(|n| n.attribute("id") == Some(id.as_str())),
                None => all.next(),
            }
        });
        let mut instances: std::collections::HashMap<String, Vec<Matrix4<f32>>> =
            Default::default();
        if let Some(scene) = scene {
            let mut stack: Vec<(roxmltree::Node<'_, '_>, Matrix4<f32>)> = scene
                .children()
                .filter(|n| n.has_tag_name("node"))
                .map(|n| (n, root_transform))
                .collect();
            while let Some((node, parent)) = stack.pop() {
                let mut world = parent;
                for t in node.children().filter(|n| {
                    n.is_element()
                        && matches!(
                            n.tag_name().name(),
                            "matrix" | "translate" | "rotate" | "scale" | "lookat" | "skew"
                        )
                }) {
                    let numbers = || -> std::result::Result<Vec<f32>, String> {
                        t.text()
                            .unwrap_or("")
                            .split_whitespace()
                            .map(|v| v.parse::<f32>().ok().filter(|v| v.is_finite()))
                            .collect::<Option<Vec<f32>>>()
                            .ok_or_else(|| {
                                format!(
                                    "node '{}': <{}> has a value that is not a finite number",
                                    node.attribute("id").unwrap_or("?"),
                                    t.tag_name().name()
                                )
                            })
                    };
                    let local = match (t.tag_name().name(), numbers()?.as_slice()) {
                        ("matrix", m) if m.len() == 16 => Matrix4::from_row_slice(m),
                        ("translate", &[x, y, z]) => {
                            Matrix4::new_translation(&Vector3::new(x, y, z))
                        }
                        ("rotate", &[x, y, z, degrees]) => {
                            let axis = nalgebra::Unit::try_new(Vector3::new(x, y, z), 1e-12)
                                .unwrap_or(Vector3::z_axis());
                            Matrix4::from_axis_angle(&axis, degrees.to_radians())
                        }
                        ("scale", &[x, y, z]) => {
                            Matrix4::new_nonuniform_scaling(&Vector3::new(x, y, z))
                        }
                        (name @ ("matrix" | "translate" | "rotate" | "scale"), values) => {
                            return Err(format!(
                                "node '{}': <{name}> has {} numbers",
                                node.attribute("id").unwrap_or("?"),
                                values.len()
                            ));
                        }
                        (name @ ("lookat" | "skew"), _) => {
                            return Err(format!(
                                "node '{}': the <{name}> transform is not supported",
                                node.attribute("id").unwrap_or("?")
                            ));
                        }
                        _ => continue,
                    };
                    world *= local;
                    blank.push(t.range());
                }
                for child in node.children() {
                    if child.has_tag_name("instance_geometry")
                        && let Some(url) = child.attribute("url")
                    {
                        instances
                            .entry(url.trim_start_matches('#').to_owned())
                            .or_default()
                            .push(world);
                    } else if child.has_tag_name("node") {
                        stack.push((child, world));
                    }
                }
            }
        }
        let mut untransformed = bytes.to_vec();
        for r in blank {
            untransformed[r].fill(b' ');
        }
        Ok(Self {
            untransformed,
            instances,
            root: root_transform,
        })
    }

    /// Where to draw geometry `id`: each of its instances, or (when no node instances it, as in
    /// files without a visual scene) once at the root transform.
    fn instances_of(&self, id: &str) -> Vec<Matrix4<f32>> {
        if self.instances.is_empty() {
            return vec![self.root];
        }
        self.instances.get(id).cloned().unwrap_or_default()
    }
}

impl TriMesh {
    /// Applies an affine transform: positions by `m`, normals by its inverse transpose, and the
    /// winding reversed when `m` mirrors (negative determinant).
    fn transform(&mut self, m: &Matrix4<f32>) {
        for p in &mut self.positions {
            let q = m.transform_point(&Point3::from(*p));
            *p = [q.x, q.y, q.z];
        }
        let linear = m.fixed_view::<3, 3>(0, 0).into_owned();
        if let Some(normals) = &mut self.normals {
            let nm = linear
                .try_inverse()
                .map(|i| i.transpose())
                .unwrap_or_else(Matrix3::identity);
            for n in normals.iter_mut() {
                let v = (nm * Vector3::from(*n))
                    .try_normalize(1e-12)
                    .unwrap_or(Vector3::z());
                *n = [v.x, v.y, v.z];
            }
        }
        if linear.determinant() < 0.0 {
            for tri in self.indices.chunks_exact_mut(3) {
                tri.swap(1, 2);
            }
        }
    }
}

/// What an STL file is, by its content (the STL format has no magic number).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum StlKind {
    /// Its size is exactly that of a binary STL of the triangle count in its header
    /// (84 + 50·count): binary, whatever its 80-byte header says (CAD exporters often begin it
    /// with `solid`, the ASCII keyword).
    Binary,
    /// Text beginning with the keyword `solid`; `bare_solid`: with no name after it on its line
    /// (OpenSCAD, FreeCAD and meshio write that; the name is optional).
    Ascii {
        /// No name follows `solid`.
        bare_solid: bool,
    },
    /// Neither.
    Neither,
}

/// What follows the keyword `solid` at the start of `bytes` (after white space), if it is there.
fn after_solid(bytes: &[u8]) -> Option<&[u8]> {
    bytes[bytes.iter().take_while(|b| b.is_ascii_whitespace()).count()..].strip_prefix(b"solid")
}

fn starts_with_solid(bytes: &[u8]) -> bool {
    after_solid(bytes).is_some()
}

fn stl_kind(bytes: &[u8]) -> StlKind {
    let count = bytes
        .get(80..84)
        .and_then(|b| b.try_into().ok())
        .map(|b| u32::from_le_bytes(b) as usize);
    if count.is_some_and(|n| Some(bytes.len()) == n.checked_mul(50).map(|b| b + 84)) {
        return StlKind::Binary;
    }
    let Some(rest) = after_solid(bytes) else {
        return StlKind::Neither;
    };
    match rest.first() {
        None | Some(b'\n' | b'\r') => StlKind::Ascii { bare_solid: true },
        Some(b) if b.is_ascii_whitespace() => {
            let line_end = rest.iter().position(|&b| b == b'\n').unwrap_or(rest.len());
            StlKind::Ascii {
                bare_solid: rest[..line_end].iter().all(u8::is_ascii_whitespace),
            }
        }
        // `solidworks...`: not the keyword.
        Some(_) => StlKind::Neither,
    }
}

fn load_gltf(path: &Path) -> Result<TriMesh> {
    let (doc, buffers, _) = gltf::import(path).map_err(|e| Error::BadMesh {
        path: path.to_owned(),
        message: e.to_string(),
    })?;
    let mut out = TriMesh::default();
    let mut normals = Vec::new();
    let mut all_have_normals = true;
    let mut colors = Vec::new();
    let scene = doc.default_scene().or_else(|| doc.scenes().next());
    let mut stack: Vec<(gltf::Node<'_>, Matrix4<f32>)> = scene
        .map(|s| s.nodes().map(|n| (n, Matrix4::identity())).collect())
        .unwrap_or_default();
    while let Some((node, parent)) = stack.pop() {
        let local = Matrix4::from(node.transform().matrix());
        let world = parent * local;
        if let Some(mesh) = node.mesh() {
            let normal_matrix = world
                .fixed_view::<3, 3>(0, 0)
                .try_inverse()
                .map(|m| m.transpose())
                .unwrap_or_else(nalgebra::Matrix3::identity);
            for prim in mesh.primitives() {
                if prim.mode() != gltf::mesh::Mode::Triangles {
                    continue;
                }
                let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
                let Some(positions) = reader.read_positions() else {
                    continue;
                };
                let base = out.positions.len() as u32;
                let count_before = out.positions.len();
                out.positions.extend(positions.map(|p| {
                    let v = world.transform_point(&Point3::new(p[0], p[1], p[2]));
                    [v.x, v.y, v.z]
                }));
                let added = out.positions.len() - count_before;
                // glTF base colours are linear; TriMesh colours follow URDF's sRGB convention.
                let linear = prim.material().pbr_metallic_roughness().base_color_factor();
                let c = [
                    linear_to_srgb(linear[0]),
                    linear_to_srgb(linear[1]),
                    linear_to_srgb(linear[2]),
                    linear[3],
                ];
                colors.extend(std::iter::repeat_n(c, added));
                match reader.read_normals() {
                    Some(ns) => normals.extend(ns.map(|n| {
                        let v = (normal_matrix * Vector3::new(n[0], n[1], n[2]))
                            .try_normalize(1e-12)
                            .unwrap_or(Vector3::z());
                        [v.x, v.y, v.z]
                    })),
                    None => all_have_normals = false,
                }
                match reader.read_indices() {
                    Some(idx) => out.indices.extend(idx.into_u32().map(|i| i + base)),
                    None => out.indices.extend((0..added as u32).map(|i| i + base)),
                }
            }
        }
        stack.extend(node.children().map(|c| (c, world)));
    }
    out.normals = (all_have_normals && normals.len() == out.positions.len()).then_some(normals);
    let coloured = colors.iter().any(|c| *c != [1.0; 4]);
    out.colors = (coloured && colors.len() == out.positions.len()).then_some(colors);
    Ok(out)
}

/// The sRGB transfer function (IEC 61966-2-1) of a linear value in 0..1.
fn linear_to_srgb(v: f32) -> f32 {
    let v = v.clamp(0.0, 1.0);
    if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

#[cfg(test)]
mod tests;
