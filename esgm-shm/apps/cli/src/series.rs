//! Numbers out of structures: which attributes of a type can be plotted, and their
//! values. An attribute is plottable when its sort is a number (`Long`, `Double`,
//! `Altitude`), or is one field of a geometric value, named with a dot (`linear.x` of a
//! `Vec`, `position.north`…).

use anyhow::bail;
use esgm_core::{EntityStructure, EntityStructureType, Value, ValueSort};

/// One plottable attribute of a type.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Field {
    /// As the user wrote it (`x`, `linear.x`).
    pub path: String,
    attribute: String,
    part: Option<&'static str>,
    /// The unit the type's sort gives it, if any (`Altitude` is in metres).
    pub unit: Option<&'static str>,
}

/// The fields of a geometric sort, or `None` for other sorts.
fn parts(sort: ValueSort) -> Option<&'static [&'static str]> {
    Some(match sort {
        ValueSort::Vec => &["x", "y", "z"],
        ValueSort::Pos2 => &["x", "y"],
        ValueSort::Position => &["north", "east"],
        ValueSort::Rotation => &["roll", "pitch", "yaw"],
        _ => return None,
    })
}

fn is_number(sort: ValueSort) -> bool {
    matches!(sort, ValueSort::Long | ValueSort::Double | ValueSort::Altitude)
}

/// Every plottable path of `ty`, for error messages.
fn plottable(ty: &EntityStructureType) -> Vec<String> {
    let mut out = Vec::new();
    for a in &ty.attributes {
        if is_number(a.sort) {
            out.push(a.name.clone());
        } else if let Some(parts) = parts(a.sort) {
            out.extend(parts.iter().map(|p| format!("{}.{p}", a.name)));
        }
    }
    out
}

fn plottable_list(ty: &EntityStructureType) -> String {
    let all = plottable(ty);
    if all.is_empty() { "none".to_owned() } else { all.join(", ") }
}

/// The field `path` of `ty` (the type of trajectory `trajectory`), or an error naming
/// what is wrong and what can be plotted instead.
pub fn resolve(ty: &EntityStructureType, trajectory: &str, path: &str) -> anyhow::Result<Field> {
    let (name, part) = match path.split_once('.') {
        Some((name, part)) => (name, Some(part)),
        None => (path, None),
    };
    let Some(attr) = ty.attributes.iter().find(|a| a.name == name) else {
        bail!(
            "`{trajectory}` ({}) has no attribute `{name}`; plottable: {}",
            ty.name,
            plottable_list(ty)
        );
    };
    let sort = attr.sort;
    match (parts(sort), part) {
        (None, None) if is_number(sort) => Ok(Field {
            path: path.to_owned(),
            attribute: name.to_owned(),
            part: None,
            unit: (sort == ValueSort::Altitude).then_some("m"),
        }),
        (Some(parts), Some(part)) => match parts.iter().find(|p| **p == part) {
            Some(p) => Ok(Field {
                path: path.to_owned(),
                attribute: name.to_owned(),
                part: Some(p),
                unit: None,
            }),
            None => bail!(
                "attribute `{name}` of `{trajectory}` ({}) is {sort} and has no field `{part}`; \
                 plot one of {}",
                ty.name,
                parts.iter().map(|p| format!("{name}.{p}")).collect::<Vec<_>>().join(", ")
            ),
        },
        (Some(parts), None) => bail!(
            "attribute `{name}` of `{trajectory}` ({}) is {sort}: plot one of its fields, {}",
            ty.name,
            parts.iter().map(|p| format!("{name}.{p}")).collect::<Vec<_>>().join(", ")
        ),
        _ => bail!(
            "attribute `{path}` of `{trajectory}` ({}) is {sort}, not a number; plottable: {}",
            ty.name,
            plottable_list(ty)
        ),
    }
}

impl Field {
    /// The field's value in `es`, or `None` where it has none (no value, or not finite).
    pub fn value(&self, es: &EntityStructure) -> Option<f64> {
        let v = match (es.get(&self.attribute)?, self.part) {
            (Value::Long(v), None) => *v as f64,
            (Value::Double(v) | Value::Altitude(v), None) => *v,
            (Value::Vec(v), Some("x")) => v.x,
            (Value::Vec(v), Some("y")) => v.y,
            (Value::Vec(v), Some("z")) => v.z,
            (Value::Pos2(v), Some("x")) => v.x,
            (Value::Pos2(v), Some("y")) => v.y,
            (Value::Position(v), Some("north")) => v.north,
            (Value::Position(v), Some("east")) => v.east,
            (Value::Rotation(v), Some("roll")) => v.roll,
            (Value::Rotation(v), Some("pitch")) => v.pitch,
            (Value::Rotation(v), Some("yaw")) => v.yaw,
            _ => return None,
        };
        v.is_finite().then_some(v)
    }

    /// The legend's label: the path, with its unit.
    pub fn label(&self) -> String {
        match self.unit {
            Some(u) => format!("{} ({u})", self.path),
            None => self.path.clone(),
        }
    }
}

#[cfg(test)]
mod tests {
    use esgm_core::library::{Image, RobotState, Twist};
    use esgm_core::{Entity, Vec3};

    use super::*;

    fn message(ty: &EntityStructureType, path: &str) -> String {
        resolve(ty, "t", path).map_or_else(|e| e.to_string(), |f| format!("ok {}", f.path))
    }

    #[test]
    fn numbers_and_geometric_fields_resolve() {
        let robot = RobotState::entity_structure_type();
        let x = resolve(&robot, "robot", "x").unwrap_or_else(|e| unreachable!("{e}"));
        let es = RobotState { x: 2.5, y: 0.0, dir: f64::NAN }.to_structure("r", 0, 0);
        assert_eq!(x.value(&es), Some(2.5));
        let dir = resolve(&robot, "robot", "dir").unwrap_or_else(|e| unreachable!("{e}"));
        assert_eq!(dir.value(&es), None, "NaN is no point");
        let twist = Twist::entity_structure_type();
        let lx = resolve(&twist, "cmd", "linear.x").unwrap_or_else(|e| unreachable!("{e}"));
        let v = Vec3 { x: 0.5, y: 0.0, z: 0.0 };
        assert_eq!(lx.value(&Twist { linear: v, angular: v }.to_structure("c", 0, 0)), Some(0.5));
    }

    #[test]
    fn errors_name_the_attribute_and_what_can_be_plotted() {
        let robot = RobotState::entity_structure_type();
        assert_eq!(
            message(&robot, "z"),
            "`t` (RobotState) has no attribute `z`; plottable: x, y, dir"
        );
        let image = Image::entity_structure_type();
        let m = message(&image, "image_data");
        assert!(m.contains("`image_data`") && m.contains("not a number"), "{m}");
        assert!(m.contains("plottable: width, height, format"), "{m}");
        let twist = Twist::entity_structure_type();
        assert!(message(&twist, "linear").contains("linear.x, linear.y, linear.z"));
        assert!(message(&twist, "linear.w").contains("no field `w`"));
    }
}
