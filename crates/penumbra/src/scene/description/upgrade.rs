//! Scene-version upgrade: the elements of a file of an older scene version
//! are rewritten to Mitsuba 3's names before plugins see them, as Mitsuba
//! 3.9 upgrades them in memory when it loads such a file.
//!
//! Every file declares its version (`<scene version="0.6.0">`; an included
//! file without one is read as its includer). What changes:
//! - before 2.0.0 (Mitsuba 0.x): parameter names are camelCase; each
//!   `name` becomes snake_case (`sampleCount` → `sample_count`, `toWorld`
//!   → `to_world`, `intIOR` → `int_ior`), parameters in
//!   [`RENAMED_PARAMETERS`] get their new name, and the texture parameters
//!   `uoffset`, `voffset`, `uscale`, `vscale` become a `to_uv` transform;
//! - from 2.0.0 on (Mitsuba 2 and 3): names are already Mitsuba 3's;
//!   nothing changes.
//!
//! Like Mitsuba 3.9, plugin names and tags are not renamed (a 0.x
//! `<lookAt>` is an unknown tag there too).

use super::xml::Elem;

/// A scene file's `version="major.minor.patch"`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct Version(pub u32, pub u32, pub u32);

impl Version {
    /// Three numbers separated by dots (or spaces), as Mitsuba reads them.
    pub fn parse(s: &str) -> Option<Version> {
        let parts: Vec<u32> = s
            .split(['.', ' '])
            .filter(|t| !t.is_empty())
            .map(|t| t.parse().ok())
            .collect::<Option<_>>()?;
        match parts[..] {
            [major, minor, patch] => Some(Version(major, minor, patch)),
            _ => None,
        }
    }
}

/// The first version whose parameter names are snake_case.
const SNAKE_CASE_SINCE: Version = Version(2, 0, 0);

/// Parameters renamed beyond the change of case, in files older than
/// 2.0.0: (plugin tag, plugin type, old name, new name).
const RENAMED_PARAMETERS: &[(&str, &str, &str, &str)] =
    &[("bsdf", "diffuse", "diffuse_reflectance", "reflectance")];

/// Upgrades `e` and everything below it, each element by its own file's
/// version.
pub(super) fn upgrade(e: &mut Elem) {
    for c in &mut e.children {
        upgrade(c);
    }
    if e.version >= SNAKE_CASE_SINCE {
        return;
    }
    for c in &mut e.children {
        if let Some((_, name)) = c.attrs.iter_mut().find(|(k, _)| k == "name") {
            *name = snake_case(name);
        }
    }
    let plugin = e.attr("type").unwrap_or_default().to_string();
    for &(tag, ty, old, new) in RENAMED_PARAMETERS {
        if e.tag == tag && plugin == ty {
            for c in &mut e.children {
                if let Some((_, name)) = c.attrs.iter_mut().find(|(k, _)| k == "name") {
                    if name == old {
                        *name = new.to_string();
                    }
                }
            }
        }
    }
    uv_parameters_to_transform(e);
}

/// Mitsuba's camelCase → snake_case: an underscore before a capital that
/// follows a lower-case letter, and that capital and the capitals right
/// after it in lower case.
pub fn snake_case(name: &str) -> String {
    let mut out = String::with_capacity(name.len() + 4);
    let mut prev_lower = false;
    let mut in_capitals = false;
    for c in name.chars() {
        if c.is_ascii_uppercase() && (prev_lower || in_capitals) {
            if prev_lower {
                out.push('_');
            }
            out.push(c.to_ascii_lowercase());
            in_capitals = true;
        } else {
            out.push(c);
            in_capitals = false;
        }
        prev_lower = c.is_ascii_lowercase();
    }
    out
}

/// `uoffset`, `voffset`, `uscale`, `vscale` (Mitsuba 0.x textures) → a
/// `<transform name="to_uv">` translating by the offsets, then scaling.
fn uv_parameters_to_transform(e: &mut Elem) {
    let mut take = |name: &str| -> Option<String> {
        let i = e
            .children
            .iter()
            .position(|c| c.tag == "float" && c.attr("name") == Some(name))?;
        let c = e.children.remove(i);
        c.attr("value").map(str::to_string)
    };
    let (uoffset, voffset) = (take("uoffset"), take("voffset"));
    let (uscale, vscale) = (take("uscale"), take("vscale"));
    if [&uoffset, &voffset, &uscale, &vscale]
        .iter()
        .all(|v| v.is_none())
    {
        return;
    }
    let op = |tag: &str, x: Option<String>, y: Option<String>| Elem {
        tag: tag.to_string(),
        attrs: [("x", x), ("y", y)]
            .into_iter()
            .filter_map(|(k, v)| Some((k.to_string(), v?)))
            .collect(),
        children: Vec::new(),
        loc: e.loc.clone(),
        version: e.version,
    };
    let transform = Elem {
        tag: "transform".to_string(),
        attrs: vec![("name".to_string(), "to_uv".to_string())],
        children: vec![
            op("translate", uoffset, voffset),
            op("scale", uscale, vscale),
        ],
        loc: e.loc.clone(),
        version: e.version,
    };
    e.children.push(transform);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn camel_case_names_become_snake_case_as_in_mitsuba() {
        for (old, new) in [
            ("sampleCount", "sample_count"),
            ("maxDepth", "max_depth"),
            ("toWorld", "to_world"),
            ("fovAxis", "fov_axis"),
            ("intIOR", "int_ior"),
            ("aBcD", "a_bc_d"),
            ("alpha", "alpha"),
            ("Alpha", "Alpha"),
            ("ABC", "ABC"),
            ("a1B", "a1B"),
            ("already_snake", "already_snake"),
        ] {
            assert_eq!(snake_case(old), new, "{old}");
        }
    }

    #[test]
    fn versions_are_three_numbers() {
        assert_eq!(Version::parse("0.6.0"), Some(Version(0, 6, 0)));
        assert_eq!(Version::parse(" 3.0.0 "), Some(Version(3, 0, 0)));
        assert!(Version::parse("0.6.0").unwrap() < SNAKE_CASE_SINCE);
        assert!(Version::parse("2.1.0").unwrap() >= SNAKE_CASE_SINCE);
        for bad in ["2.0", "banana", "3.0.x", "", "1.2.3.4", "-1.0.0"] {
            assert_eq!(Version::parse(bad), None, "{bad}");
        }
    }
}
