//! A JSON document as TOML, for `trainer inspect --format toml`, written by
//! the `toml` crate: tables for objects, arrays of tables for arrays of
//! objects, inline arrays otherwise. Two things TOML or the crate would
//! otherwise do differently are settled here first: TOML has no null (a
//! null field is left out, a null in an array is `nan`), and a blob's
//! parameters are f32, so a float that is an f32 is shown as that f32's
//! shortest decimal (`-28.123835`, not the widened `-28.123834609985352`).
//! The crate's own spelling stands where TOML allows several (a float
//! without an exponent, a string holding `"` as a literal string `'x"y'`):
//! every value reads back to the same bits.

use serde_json::Value;

/// `value` (an object) as a TOML document; anything else gives an empty one.
pub fn to_toml(value: &Value) -> String {
    match to_toml_value(value) {
        Some(toml::Value::Table(table)) => toml::to_string(&table).unwrap_or_default(),
        _ => String::new(),
    }
}

/// `v` as a TOML value: `None` for a null (left out of its table).
fn to_toml_value(v: &Value) -> Option<toml::Value> {
    Some(match v {
        Value::Null => return None,
        Value::Bool(b) => toml::Value::Boolean(*b),
        Value::Number(n) => match (n.as_i64(), n.as_f64()) {
            (Some(i), _) => toml::Value::Integer(i),
            (None, Some(f)) => toml::Value::Float(shortest_f32_if_exact(f)),
            // A u64 past i64::MAX has no TOML integer; its decimal is kept.
            (None, None) => toml::Value::String(n.to_string()),
        },
        Value::String(s) => toml::Value::String(s.clone()),
        Value::Array(items) => toml::Value::Array(
            items
                .iter()
                .map(|item| to_toml_value(item).unwrap_or(toml::Value::Float(f64::NAN)))
                .collect(),
        ),
        Value::Object(map) => toml::Value::Table(
            map.iter()
                .filter_map(|(k, v)| Some((k.clone(), to_toml_value(v)?)))
                .collect(),
        ),
    })
}

/// `f`, or where `f` is exactly an f32, the f64 nearest that f32's shortest
/// decimal, which the writer then prints as that decimal.
fn shortest_f32_if_exact(f: f64) -> f64 {
    // Exact comparison on purpose: only a value that is an f32 is shown as one.
    #[allow(clippy::float_cmp)]
    let is_f32 = f64::from(f as f32) == f;
    if is_f32 && f.is_finite() {
        format!("{:?}", f as f32).parse().unwrap_or(f)
    } else {
        f
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
            "\"a key\" = 'x\"y'\ncenters = 2\nkind = \"gaussian-rbf\"\nvalid = true\n\
             \n[rbf]\nconstant_dph = -3.25\nwidths = [0.5, 1.0]\n\
             \n[[training_ranges]]\ninput = \"T [°C]\"\nmin = -10.0\n"
        );
        // What it writes reads back as the document without its nulls.
        let back: toml::Table = toml::from_str(&toml).unwrap();
        assert_eq!(back["training_ranges"][0]["min"].as_float(), Some(-10.0));
        assert!(!back.contains_key("serial"));
    }

    #[test]
    fn floats_keep_a_point_and_specials_are_spelled_as_toml_does() {
        let doc = |v: Value| to_toml(&serde_json::json!({ "x": v }));
        assert_eq!(doc(serde_json::json!(3.0)), "x = 3.0\n");
        // The crate spells floats without an exponent; they read back the same.
        for x in [1e300f64, 3.2e-8, -0.0] {
            let back: toml::Table = toml::from_str(&doc(serde_json::json!(x))).unwrap();
            assert_eq!(back["x"].as_float().map(f64::to_bits), Some(x.to_bits()), "{x}");
        }
        assert_eq!(doc(serde_json::json!(f64::from(-28.123835f32))), "x = -28.123835\n");
        assert_eq!(doc(serde_json::json!(0.1)), "x = 0.1\n");
        assert_eq!(doc(serde_json::json!([1, null])), "x = [1, nan]\n");
    }
}
