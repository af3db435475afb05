//! The URDF checked before it is read: every element and attribute a robot needs, numbers finite,
//! names unique, errors naming the element.

use super::*;

pub(super) fn parse_finite(text: &str, what: &str) -> Result<f64> {
    let v: f64 = text.parse().map_err(|_| Error::NotANumber {
        what: what.to_owned(),
        text: text.to_owned(),
    })?;
    if !v.is_finite() {
        return Err(Error::NonFinite {
            what: what.to_owned(),
            value: v,
        });
    }
    Ok(v)
}

/// Checks well-formedness and joint types with line numbers, which urdf-rs does not report.
pub(super) fn validate_xml(text: &str, origin: &str) -> Result<()> {
    let doc = roxmltree::Document::parse(text).map_err(|e| Error::MalformedUrdf {
        origin: origin.to_owned(),
        message: e.to_string(),
    })?;
    let root = doc.root_element();
    if root.tag_name().name() != "robot" {
        return Err(Error::MalformedUrdf {
            origin: origin.to_owned(),
            message: format!(
                "the root element is <{}>, expected <robot>",
                root.tag_name().name()
            ),
        });
    }
    for joint in root.children().filter(|n| n.has_tag_name("joint")) {
        let kind = joint.attribute("type").unwrap_or("");
        let name = joint.attribute("name").unwrap_or("?");
        let line = doc.text_pos_at(joint.range().start).row;
        if !matches!(
            kind,
            "revolute" | "continuous" | "prismatic" | "fixed" | "floating" | "planar"
        ) {
            return Err(Error::UnknownJointType {
                origin: origin.to_owned(),
                line,
                joint: name.to_owned(),
                kind: kind.to_owned(),
            });
        }
        let bad = |line: u32, message: String| Error::BadJoint {
            origin: format!("{origin}:{line}"),
            joint: name.to_owned(),
            message,
        };
        // The URDF spec requires a <limit> on revolute and prismatic joints; without one,
        // urdf-rs reads limits [0, 0] and the joint silently cannot move.
        if matches!(kind, "revolute" | "prismatic")
            && !joint.children().any(|n| n.has_tag_name("limit"))
        {
            return Err(bad(
                line,
                format!(
                    "a {kind} joint needs a <limit> (lower, upper, effort, velocity); none is given"
                ),
            ));
        }
        // Every number of the joint's elements, token by token: a decimal comma from a
        // comma-locale exporter ("0,25") is named here, not as a wrong element count.
        for child in joint.children().filter(|n| {
            n.is_element()
                && matches!(
                    n.tag_name().name(),
                    "origin"
                        | "axis"
                        | "limit"
                        | "dynamics"
                        | "mimic"
                        | "calibration"
                        | "safety_controller"
                )
        }) {
            let tag = child.tag_name().name();
            for attr in child
                .attributes()
                .filter(|a| !(tag == "mimic" && a.name() == "joint"))
            {
                if let Some(token) = attr
                    .value()
                    .split_whitespace()
                    .find(|t| t.parse::<f64>().is_err())
                {
                    let line = doc.text_pos_at(child.range().start).row;
                    return Err(bad(
                        line,
                        format!(
                            "<{tag} {}=\"{}\">: '{token}' is not a number",
                            attr.name(),
                            attr.value()
                        ),
                    ));
                }
            }
        }
    }
    Ok(())
}
