//! `package://` URIs resolved as ROS does: the package path's folders searched for `package.xml`
//! (its `<name>`), not below a folder that is a package.

use super::*;

/// Folders searched for `package://NAME/...` mesh URIs, in order.
///
/// For each folder `D`, `package://NAME/rest` resolves to `D/rest` when `D` itself is named
/// `NAME`, to `D/NAME/rest`, or to `P/rest` for the first folder `P` below `D` whose
/// `package.xml` names `NAME` (see [`PackagePath::find_package`]).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct PackagePath(pub Vec<PathBuf>);

impl PackagePath {
    /// Adds the entries of a `ROS_PACKAGE_PATH`-style list (`:`-separated).
    pub fn extend_from_env_list(&mut self, list: &str) {
        self.0
            .extend(list.split(':').filter(|s| !s.is_empty()).map(PathBuf::from));
    }

    /// The folder of package `package`: for each entry `D` in order, `D` itself when it is that
    /// package, then `D/package`, then the folders below `D` searched for a `package.xml` whose
    /// `<name>` is `package`, as ROS does (rospack, REP 128): a search does not descend below a
    /// folder that is a package, nor into one holding `CATKIN_IGNORE`, `COLCON_IGNORE` or
    /// `AMENT_IGNORE`, nor into hidden folders.
    pub fn find_package(&self, package: &str) -> Option<PathBuf> {
        self.0.iter().find_map(|dir| {
            let nested = dir.join(package);
            if dir.file_name().is_some_and(|n| n == package) && dir.is_dir() {
                Some(dir.clone())
            } else if nested.is_dir() {
                Some(nested)
            } else {
                find_package_below(dir, package, 0, &mut Default::default())
            }
        })
    }
}

impl PackagePath {
    /// Why `package` was not found, for an error message: the folders searched, how, and what
    /// to do.
    pub fn not_found(&self, package: &str) -> String {
        let searched: Vec<String> = self.0.iter().map(|p| p.display().to_string()).collect();
        format!(
            "package '{package}' is not found in the package path [{}] (each folder, its subfolder '{package}', and the package.xml files below it); add the folder that holds it with --package-path (or ROS_PACKAGE_PATH)",
            searched.join(", ")
        )
    }
}

/// The `<name>` of the package whose `package.xml` is in `dir`, if there is one.
pub(super) fn package_name(dir: &Path) -> Option<String> {
    let text = std::fs::read_to_string(dir.join("package.xml")).ok()?;
    let doc = roxmltree::Document::parse(&text).ok()?;
    doc.root_element()
        .children()
        .find(|n| n.has_tag_name("name"))
        .and_then(|n| n.text())
        .map(|t| t.trim().to_owned())
}

/// Depth-first search below `dir` for the folder of package `package` (see
/// [`PackagePath::find_package`]); folders are visited in name order, 16 levels at most.
pub(super) fn find_package_below(
    dir: &Path,
    package: &str,
    depth: usize,
    seen: &mut std::collections::HashSet<PathBuf>,
) -> Option<PathBuf> {
    const MAX_DEPTH: usize = 16;
    // Each folder once: a symbolic link back up the tree is not walked again.
    if depth > MAX_DEPTH || !seen.insert(dir.canonicalize().ok()?) {
        return None;
    }
    if dir.join("package.xml").is_file() {
        // A package: it is the one or the search stops here.
        return (package_name(dir).as_deref() == Some(package)).then(|| dir.to_owned());
    }
    if ["CATKIN_IGNORE", "COLCON_IGNORE", "AMENT_IGNORE"]
        .iter()
        .any(|f| dir.join(f).exists())
    {
        return None;
    }
    let mut children: Vec<PathBuf> = std::fs::read_dir(dir)
        .ok()?
        .filter_map(|e| e.ok())
        .filter(|e| !e.file_name().to_string_lossy().starts_with('.'))
        .map(|e| e.path())
        .filter(|p| p.is_dir())
        .collect();
    children.sort();
    children
        .iter()
        .find_map(|c| find_package_below(c, package, depth + 1, seen))
}

pub(super) fn resolve_mesh_uri(uri: &str, link: &str, raw: &Raw<'_>) -> Result<PathBuf> {
    let path = if let Some(rest) = uri.strip_prefix("package://") {
        let (package, file) = rest.split_once('/').unwrap_or((rest, ""));
        let dir = raw
            .found
            .borrow_mut()
            .entry(package.to_owned())
            .or_insert_with(|| raw.packages.find_package(package))
            .clone()
            .ok_or_else(|| Error::UnknownPackage {
                origin: raw.origin.to_owned(),
                link: link.to_owned(),
                uri: uri.to_owned(),
                package: package.to_owned(),
                why: raw.packages.not_found(package),
            })?;
        dir.join(file)
    } else if let Some(rest) = uri.strip_prefix("file://") {
        PathBuf::from(rest)
    } else if uri.contains("://") {
        return Err(Error::UnsupportedUri {
            origin: raw.origin.to_owned(),
            link: link.to_owned(),
            uri: uri.to_owned(),
        });
    } else {
        let p = PathBuf::from(uri);
        match raw.base_dir {
            Some(base) if p.is_relative() => base.join(p),
            _ => p,
        }
    };
    if !path.is_file() {
        return Err(Error::MissingMesh {
            origin: raw.origin.to_owned(),
            link: link.to_owned(),
            uri: uri.to_owned(),
            resolved: path,
        });
    }
    Ok(path)
}
