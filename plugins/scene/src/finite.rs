//! Every number in a scene file is finite: TOML allows `nan` and `inf`, and a NaN that slips
//! through (a camera at `eye = [1.85, 0, nan]`) panics deep inside the renderer instead of
//! being refused by name.

use toml::{Table, Value};

/// The dotted path (`camera.pose.eye[2]`) and value of the first non-finite float in `table`,
/// tables walked in key order (alphabetical), arrays in index order.
pub fn first_non_finite(table: &Table) -> Option<(String, f64)> {
    table
        .iter()
        .find_map(|(key, value)| walk(key.clone(), value))
}

fn walk(path: String, value: &Value) -> Option<(String, f64)> {
    match value {
        Value::Float(v) if !v.is_finite() => Some((path, *v)),
        Value::Array(items) => items
            .iter()
            .enumerate()
            .find_map(|(i, v)| walk(format!("{path}[{i}]"), v)),
        Value::Table(t) => t
            .iter()
            .find_map(|(key, v)| walk(format!("{path}.{key}"), v)),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_the_first_nan_or_infinity_with_its_path() {
        let t: Table = toml::from_str(
            "a = 1.0\n[camera.pose]\neye = [1.0, 2.0, nan]\n[[props]]\nsize = [1.0, -inf]\n",
        )
        .expect("toml");
        let (path, v) = first_non_finite(&t).expect("found");
        assert_eq!(path, "camera.pose.eye[2]");
        assert!(v.is_nan());
        let t: Table =
            toml::from_str("[[props]]\nname = 'x'\n[[props]]\nsize = [1.0, -inf]\n").expect("toml");
        assert_eq!(
            first_non_finite(&t),
            Some(("props[1].size[1]".to_owned(), f64::NEG_INFINITY))
        );
        let t: Table = toml::from_str("a = 1e308\nb = [0.0, -0.0]\n").expect("toml");
        assert_eq!(first_non_finite(&t), None);
    }
}
