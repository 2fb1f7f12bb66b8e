//! A JSON document as TOML, for `trainer inspect --format toml`: tables for
//! objects, arrays of tables for arrays of objects, inline arrays otherwise.
//! TOML has no null: a null field is left out, a null in an array is `nan`.

use std::fmt::Write as _;

use serde_json::Value;

/// `value` (an object) as a TOML document.
pub fn to_toml(value: &Value) -> String {
    let mut out = String::new();
    if let Value::Object(map) = value {
        write_table(&mut out, &[], map);
    }
    out
}

/// Whether `v` is written as a table or an array of tables rather than `key = value`.
fn is_table(v: &Value) -> bool {
    match v {
        Value::Object(_) => true,
        Value::Array(items) => !items.is_empty() && items.iter().all(Value::is_object),
        _ => false,
    }
}

fn write_table(out: &mut String, path: &[String], map: &serde_json::Map<String, Value>) {
    for (k, v) in map {
        if !v.is_null() && !is_table(v) {
            let _ = writeln!(out, "{} = {}", key(k), inline(v));
        }
    }
    for (k, v) in map {
        let mut sub = path.to_vec();
        sub.push(key(k));
        match v {
            Value::Object(m) => {
                let _ = writeln!(out, "\n[{}]", sub.join("."));
                write_table(out, &sub, m);
            }
            Value::Array(items) if is_table(v) => {
                for item in items {
                    let _ = writeln!(out, "\n[[{}]]", sub.join("."));
                    if let Value::Object(m) = item {
                        write_table(out, &sub, m);
                    }
                }
            }
            _ => {}
        }
    }
}

/// A key, bare when TOML allows it, else quoted.
fn key(k: &str) -> String {
    if !k.is_empty() && k.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-') {
        k.to_owned()
    } else {
        Value::String(k.to_owned()).to_string()
    }
}

/// A value in inline form.
fn inline(v: &Value) -> String {
    match v {
        Value::Null => "nan".to_owned(),
        Value::Bool(b) => b.to_string(),
        Value::Number(n) => match (n.as_i64(), n.as_u64(), n.as_f64()) {
            (Some(i), _, _) => i.to_string(),
            (_, Some(u), _) => u.to_string(),
            (_, _, Some(f)) => float(f),
            _ => n.to_string(),
        },
        // A JSON string's escapes (\" \\ \n \uXXXX …) are TOML's basic string's.
        Value::String(_) => v.to_string(),
        Value::Array(items) => format!("[{}]", items.iter().map(inline).collect::<Vec<_>>().join(", ")),
        Value::Object(map) => format!(
            "{{ {} }}",
            map.iter()
                .filter(|(_, v)| !v.is_null())
                .map(|(k, v)| format!("{} = {}", key(k), inline(v)))
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// A float TOML reads back to the same value: always with a `.` or exponent.
fn float(f: f64) -> String {
    if f.is_nan() {
        return "nan".to_owned();
    }
    if f.is_infinite() {
        return if f > 0.0 { "inf" } else { "-inf" }.to_owned();
    }
    // Debug is the shortest form that reads back exactly, with a `.` or an
    // exponent; a blob's parameters are f32, shown as the f32 they are.
    // Exact comparison on purpose: only a value that is an f32 is shown as one.
    #[allow(clippy::float_cmp)]
    let is_f32 = f64::from(f as f32) == f;
    if is_f32 {
        format!("{:?}", f as f32)
    } else {
        format!("{f:?}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn objects_become_tables_and_nulls_are_left_out() {
        let v = serde_json::json!({
            "kind": "gaussian-rbf", "centers": 2, "serial": null, "valid": true,
            "rbf": {"widths": [0.5, 1.0], "constant_dph": -3.25},
            "training_ranges": [{"input": "T [°C]", "min": -10.0, "max": null}],
            "a key": "x\"y",
        });
        let toml = to_toml(&v);
        assert_eq!(
            toml,
            "\"a key\" = \"x\\\"y\"\ncenters = 2\nkind = \"gaussian-rbf\"\nvalid = true\n\
             \n[rbf]\nconstant_dph = -3.25\nwidths = [0.5, 1.0]\n\
             \n[[training_ranges]]\ninput = \"T [°C]\"\nmin = -10.0\n"
        );
    }

    #[test]
    fn floats_keep_a_point_and_specials_are_spelled_as_toml_does() {
        assert_eq!(float(3.0), "3.0");
        assert_eq!(float(1e300), "1e300");
        assert_eq!(float(f64::from(-28.123835f32)), "-28.123835");
        assert_eq!(float(f64::NEG_INFINITY), "-inf");
        assert_eq!(inline(&serde_json::json!([1, null])), "[1, nan]");
    }
}
