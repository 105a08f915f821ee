//! RIHS01 type hashes (REP 2011), computed from the `.msg` definitions we ship
//! (`starc_pipeline::record::schema`), as rosidl computes them at build time: the type's
//! description and every type it references (sorted by name), fields as name and type (type id,
//! array capacity, string capacity, nested type name), default values left out, written as
//! Python's `json.dumps` with `", "` and `": "` separators, then SHA-256.

use starc_pipeline::record::schema::own_fields;
use std::collections::BTreeMap;
use std::fmt::Write;

use crate::LinkError;

/// One field's type as type_description_interfaces/FieldType describes it.
#[derive(Debug, Clone, PartialEq, Eq)]
struct FieldType {
    type_id: u8,
    capacity: u64,
    string_capacity: u64,
    nested_type_name: String,
}

/// `FieldType` ids of the scalar types (type_description_interfaces/msg/FieldType).
fn scalar_id(name: &str) -> Option<u8> {
    Some(match name {
        "int8" => 2,
        "uint8" | "char" => 3,
        "int16" => 4,
        "uint16" => 5,
        "int32" => 6,
        "uint32" => 7,
        "int64" => 8,
        "uint64" => 9,
        "float32" => 10,
        "float64" => 11,
        "bool" => 15,
        "byte" => 16,
        "string" => 17,
        "wstring" => 18,
        _ => return None,
    })
}

/// `pkg/Type` -> `pkg/msg/Type`.
fn full_name(name: &str) -> String {
    if name.contains("/msg/") {
        name.to_string()
    } else {
        name.replacen('/', "/msg/", 1)
    }
}

/// Reads one field's type: `T`, `T[]`, `T[N]`, `T[<=N]`, `string<=N`, nested `pkg/Type`.
fn field_type(text: &str) -> Option<FieldType> {
    let (base, array) = match text.find('[') {
        Some(i) => (&text[..i], Some(text[i + 1..].strip_suffix(']')?)),
        None => (text, None),
    };
    let (base, string_capacity) = match base.split_once("<=") {
        Some((b, n)) => (b, n.parse().ok()?),
        None => (base, 0),
    };
    let (mut type_id, nested_type_name) = match scalar_id(base) {
        Some(id) if string_capacity > 0 && id == 17 => (21, String::new()),
        Some(id) if string_capacity > 0 && id == 18 => (22, String::new()),
        Some(id) => (id, String::new()),
        None if base.contains('/') => (1, full_name(base)),
        None => return None,
    };
    let mut capacity = 0;
    match array {
        None => {}
        Some("") => type_id += 144,
        Some(bound) => match bound.strip_prefix("<=") {
            Some(n) => {
                type_id += 96;
                capacity = n.parse().ok()?;
            }
            None => {
                type_id += 48;
                capacity = bound.parse().ok()?;
            }
        },
    }
    Some(FieldType { type_id, capacity, string_capacity, nested_type_name })
}

/// A type's fields as (name, type), constants left out.
fn fields(type_name: &str) -> Result<Vec<(String, FieldType)>, LinkError> {
    let err = |reason: String| LinkError::TypeHash { type_name: type_name.into(), reason };
    let text = own_fields(type_name).ok_or_else(|| err("not a type the schema knows".into()))?;
    let mut out = Vec::new();
    for line in text.lines().map(str::trim).filter(|l| !l.is_empty() && !l.starts_with('#')) {
        let mut words = line.split_whitespace();
        let (Some(ty), Some(name)) = (words.next(), words.next()) else {
            return Err(err(format!("cannot read {line:?}")));
        };
        if name.contains('=') || words.next().is_some_and(|w| w.starts_with('=')) {
            continue; // a constant
        }
        let ft = field_type(ty).ok_or_else(|| err(format!("cannot read the type of {line:?}")))?;
        out.push((name.to_string(), ft));
    }
    Ok(out)
}

fn write_description(out: &mut String, type_name: &str, fields: &[(String, FieldType)]) {
    let _ = write!(out, "{{\"type_name\": \"{type_name}\", \"fields\": [");
    for (i, (name, t)) in fields.iter().enumerate() {
        if i > 0 {
            out.push_str(", ");
        }
        let _ = write!(
            out,
            "{{\"name\": \"{name}\", \"type\": {{\"type_id\": {}, \"capacity\": {}, \"string_capacity\": {}, \
             \"nested_type_name\": \"{}\"}}}}",
            t.type_id, t.capacity, t.string_capacity, t.nested_type_name
        );
    }
    out.push_str("]}");
}

/// The text rosidl hashes for `type_name`: its description and every type it references.
pub fn hashable_json(type_name: &str) -> Result<String, LinkError> {
    let top = full_name(type_name);
    let own = fields(&top)?;
    let mut referenced: BTreeMap<String, Vec<(String, FieldType)>> = BTreeMap::new();
    let mut queue: Vec<String> = own.iter().map(|(_, t)| t.nested_type_name.clone()).collect();
    while let Some(name) = queue.pop() {
        if name.is_empty() || referenced.contains_key(&name) {
            continue;
        }
        let f = fields(&name)?;
        queue.extend(f.iter().map(|(_, t)| t.nested_type_name.clone()));
        referenced.insert(name, f);
    }
    let mut out = String::from("{\"type_description\": ");
    write_description(&mut out, &top, &own);
    out.push_str(", \"referenced_type_descriptions\": [");
    for (i, (name, f)) in referenced.iter().enumerate() {
        if i > 0 {
            out.push_str(", ");
        }
        write_description(&mut out, name, f);
    }
    out.push_str("]}");
    Ok(out)
}

/// `RIHS01_<64 hex digits>` for `type_name`.
pub fn rihs01(type_name: &str) -> Result<String, LinkError> {
    let json = hashable_json(type_name)?;
    let digest = ring::digest::digest(&ring::digest::SHA256, json.as_bytes());
    let mut out = String::from("RIHS01_");
    for b in digest.as_ref() {
        let _ = write!(out, "{b:02x}");
    }
    Ok(out)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// Published Jazzy hashes: the four the ROS 2 issue names (prefixes), and full ones from
    /// rosidl-generated `*__description.c` files of a Jazzy build.
    #[test]
    fn hashes_equal_the_published_jazzy_values() {
        let prefixes = [
            ("sensor_msgs/msg/PointCloud2", "RIHS01_9198cabf"),
            ("sensor_msgs/msg/Imu", "RIHS01_7d9a00ff"),
            ("nav_msgs/msg/Odometry", "RIHS01_3cc97dc7"),
            ("tf2_msgs/msg/TFMessage", "RIHS01_e369d0f0"),
        ];
        for (name, prefix) in prefixes {
            let h = rihs01(name).unwrap();
            assert!(h.starts_with(prefix), "{name}: {h}");
            assert_eq!(h.len(), 7 + 64);
        }
        let full = [
            ("builtin_interfaces/msg/Time", "b106235e25a4c5ed35098aa0a61a3ee9c9b18d197f398b0e4206cea9acf9c197"),
            ("geometry_msgs/msg/Point", "6963084842a9b04494d6b2941d11444708d892da2f4b09843b9c43f42a7f6881"),
            ("geometry_msgs/msg/Pose", "d501954e9476cea2996984e812054b68026ae0bfae789d9a10b23daf35cc90fa"),
            ("geometry_msgs/msg/Vector3", "cc12fe83e4c02719f1ce8070bfd14aecd40f75a96696a67a2a1f37f7dbb0765d"),
            ("std_msgs/msg/Header", "f49fb3ae2cf070f793645ff749683ac6b06203e41c891e17701b1cb597ce6a01"),
            ("vision_msgs/msg/Detection3D", "ddd703be132ab0b69d33121f1bb034132bfbb3b0ac5f9fb1516005ba1c8a265b"),
            ("vision_msgs/msg/Detection3DArray", "793f5eab9595ac1c0da07873cc859db42eae51f0ee76056db8562515d830e018"),
        ];
        for (name, hex) in full {
            assert_eq!(rihs01(name).unwrap(), format!("RIHS01_{hex}"), "{name}");
        }
    }

    #[test]
    fn field_types_read_as_rosidl_numbers_them() {
        let t = |s| field_type(s).unwrap();
        assert_eq!(t("float64[36]").type_id, 59);
        assert_eq!(t("float64[36]").capacity, 36);
        assert_eq!(t("uint8[]").type_id, 147);
        assert_eq!(t("int32[<=4]").type_id, 102);
        assert_eq!(t("string<=8").type_id, 21);
        assert_eq!(t("string<=8").string_capacity, 8);
        assert_eq!(t("geometry_msgs/Point[]").type_id, 145);
        assert_eq!(t("geometry_msgs/Point[]").nested_type_name, "geometry_msgs/msg/Point");
        assert!(field_type("float128").is_none());
        assert!(field_type("uint8[x]").is_none());
        assert!(rihs01("sensor_msgs/msg/Nope").is_err());
    }
}
