//! ROS 2 parameter values, declarations and the typed view a node's config is built from.

use std::collections::BTreeMap;
use std::fmt;

/// A parameter value (the ROS 2 parameter types).
#[derive(Debug, Clone, PartialEq)]
pub enum ParamValue {
    /// `bool`.
    Bool(bool),
    /// `integer` (int64).
    Integer(i64),
    /// `double`.
    Double(f64),
    /// `string`.
    String(String),
    /// `bool[]`.
    BoolArray(Vec<bool>),
    /// `integer[]`.
    IntegerArray(Vec<i64>),
    /// `double[]`.
    DoubleArray(Vec<f64>),
    /// `string[]`.
    StringArray(Vec<String>),
}

impl ParamValue {
    /// A double from an `f32` default as it is written (`0.012`), not as its binary value
    /// widens (`0.012000000104308128`), so docs and `param get` show what the code says.
    pub fn from_f32(x: f32) -> ParamValue {
        ParamValue::Double(x.to_string().parse().unwrap_or(f64::from(x)))
    }

    /// The ROS 2 type name (`double`, `string[]`, ...).
    pub fn type_name(&self) -> &'static str {
        match self {
            ParamValue::Bool(_) => "bool",
            ParamValue::Integer(_) => "integer",
            ParamValue::Double(_) => "double",
            ParamValue::String(_) => "string",
            ParamValue::BoolArray(_) => "bool[]",
            ParamValue::IntegerArray(_) => "integer[]",
            ParamValue::DoubleArray(_) => "double[]",
            ParamValue::StringArray(_) => "string[]",
        }
    }

    /// Converts a YAML value as ROS 2 does for `-p name:=value` and params files.
    pub fn from_yaml(v: &serde_yaml::Value) -> Result<ParamValue, String> {
        use serde_yaml::Value as Y;
        Ok(match v {
            Y::Bool(b) => ParamValue::Bool(*b),
            Y::Number(n) if n.is_i64() => ParamValue::Integer(n.as_i64().unwrap_or(0)),
            Y::Number(n) => ParamValue::Double(n.as_f64().unwrap_or(f64::NAN)),
            Y::String(s) => ParamValue::String(s.clone()),
            Y::Sequence(items) if items.is_empty() => ParamValue::StringArray(vec![]),
            Y::Sequence(items) => {
                if items.iter().all(|i| matches!(i, Y::Bool(_))) {
                    ParamValue::BoolArray(items.iter().filter_map(Y::as_bool).collect())
                } else if items.iter().all(|i| i.as_i64().is_some()) {
                    ParamValue::IntegerArray(items.iter().filter_map(Y::as_i64).collect())
                } else if items.iter().all(|i| matches!(i, Y::Number(_))) {
                    ParamValue::DoubleArray(items.iter().filter_map(Y::as_f64).collect())
                } else if items.iter().all(|i| matches!(i, Y::String(_))) {
                    ParamValue::StringArray(items.iter().filter_map(|i| i.as_str().map(str::to_string)).collect())
                } else {
                    return Err("an array must hold values of one type".into());
                }
            }
            Y::Null => return Err("empty value".into()),
            Y::Mapping(_) => return Err("a mapping is not a parameter value".into()),
            Y::Tagged(_) => return Err("tagged YAML values are not parameter values".into()),
        })
    }

    /// Parses the right-hand side of `-p name:=value` (YAML syntax).
    pub fn parse(text: &str) -> Result<ParamValue, String> {
        let y: serde_yaml::Value = serde_yaml::from_str(text).map_err(|e| format!("not a YAML value: {e}"))?;
        ParamValue::from_yaml(&y)
    }
}

impl fmt::Display for ParamValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ParamValue::Bool(b) => write!(f, "{b}"),
            ParamValue::Integer(i) => write!(f, "{i}"),
            ParamValue::Double(d) => write!(f, "{d:?}"),
            ParamValue::String(s) => write!(f, "{s}"),
            ParamValue::BoolArray(v) => write!(f, "{v:?}"),
            ParamValue::IntegerArray(v) => write!(f, "{v:?}"),
            ParamValue::DoubleArray(v) => write!(f, "{v:?}"),
            ParamValue::StringArray(v) => write!(f, "{v:?}"),
        }
    }
}

/// A declared parameter: name, default, unit and meaning (what the node docs list).
#[derive(Debug, Clone, PartialEq)]
pub struct ParamDecl {
    /// Name.
    pub name: &'static str,
    /// Default value (also fixes the type).
    pub default: ParamValue,
    /// Unit, or "" for none.
    pub unit: &'static str,
    /// Meaning.
    pub description: &'static str,
}

/// Why parameters were refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ParamError {
    /// A value has the wrong type.
    #[error("parameter {name}: expected {expected}, got {got} ({value})")]
    WrongType {
        /// Name.
        name: String,
        /// Expected type.
        expected: &'static str,
        /// Given type.
        got: &'static str,
        /// Given value.
        value: String,
    },
    /// A value is out of range or otherwise invalid.
    #[error("parameter {name}: {reason}")]
    Invalid {
        /// Name.
        name: String,
        /// What is wrong.
        reason: String,
    },
    /// A parameter that the node does not declare.
    #[error("parameter {0} is not declared by this node")]
    Undeclared(String),
}

/// A node's parameter values after overrides, checked against its declarations.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Params {
    values: BTreeMap<String, ParamValue>,
}

impl Params {
    /// Declared defaults overridden by `overrides` (integers widen to doubles where a double is
    /// declared). Overrides the node does not declare are kept (ROS 2 allows undeclared
    /// overrides; `use_sim_time` is one) but typed ones must match their declaration.
    pub fn resolve(decls: &[ParamDecl], overrides: &BTreeMap<String, ParamValue>) -> Result<Params, ParamError> {
        let mut values: BTreeMap<String, ParamValue> =
            decls.iter().map(|d| (d.name.to_string(), d.default.clone())).collect();
        for (name, v) in overrides {
            let v = match decls.iter().find(|d| d.name == name) {
                Some(d) => coerce(name, &d.default, v.clone())?,
                None => v.clone(),
            };
            values.insert(name.clone(), v);
        }
        Ok(Params { values })
    }
    /// Sets one value at run time, checked against the declaration's type.
    pub fn set(&mut self, decls: &[ParamDecl], name: &str, v: ParamValue) -> Result<(), ParamError> {
        let d = decls.iter().find(|d| d.name == name).ok_or_else(|| ParamError::Undeclared(name.into()))?;
        let v = coerce(name, &d.default, v)?;
        self.values.insert(name.to_string(), v);
        Ok(())
    }
    /// All values.
    pub fn iter(&self) -> impl Iterator<Item = (&String, &ParamValue)> {
        self.values.iter()
    }
    /// A value.
    pub fn get(&self, name: &str) -> Option<&ParamValue> {
        self.values.get(name)
    }
    fn need(&self, name: &str) -> Result<&ParamValue, ParamError> {
        self.values.get(name).ok_or_else(|| ParamError::Invalid { name: name.into(), reason: "not set".into() })
    }
    /// A `double`.
    pub fn f64(&self, name: &str) -> Result<f64, ParamError> {
        match self.need(name)? {
            ParamValue::Double(d) => Ok(*d),
            ParamValue::Integer(i) => Ok(*i as f64),
            v => Err(wrong(name, "double", v)),
        }
    }
    /// An `integer`.
    pub fn i64(&self, name: &str) -> Result<i64, ParamError> {
        match self.need(name)? {
            ParamValue::Integer(i) => Ok(*i),
            v => Err(wrong(name, "integer", v)),
        }
    }
    /// A `bool`.
    pub fn bool(&self, name: &str) -> Result<bool, ParamError> {
        match self.need(name)? {
            ParamValue::Bool(b) => Ok(*b),
            v => Err(wrong(name, "bool", v)),
        }
    }
    /// A `string`.
    pub fn string(&self, name: &str) -> Result<String, ParamError> {
        match self.need(name)? {
            ParamValue::String(s) => Ok(s.clone()),
            v => Err(wrong(name, "string", v)),
        }
    }
    /// A `double[]`.
    pub fn f64_array(&self, name: &str) -> Result<Vec<f64>, ParamError> {
        match self.need(name)? {
            ParamValue::DoubleArray(v) => Ok(v.clone()),
            ParamValue::IntegerArray(v) => Ok(v.iter().map(|&i| i as f64).collect()),
            v => Err(wrong(name, "double[]", v)),
        }
    }
    /// A `string[]`.
    pub fn string_array(&self, name: &str) -> Result<Vec<String>, ParamError> {
        match self.need(name)? {
            ParamValue::StringArray(v) => Ok(v.clone()),
            v => Err(wrong(name, "string[]", v)),
        }
    }
    /// An error for `name` with a reason (for config validation).
    pub fn invalid(name: &str, reason: impl Into<String>) -> ParamError {
        ParamError::Invalid { name: name.into(), reason: reason.into() }
    }
}

fn wrong(name: &str, expected: &'static str, v: &ParamValue) -> ParamError {
    ParamError::WrongType { name: name.into(), expected, got: v.type_name(), value: v.to_string() }
}

fn coerce(name: &str, default: &ParamValue, v: ParamValue) -> Result<ParamValue, ParamError> {
    Ok(match (default, v) {
        (ParamValue::Double(_), ParamValue::Integer(i)) => ParamValue::Double(i as f64),
        (ParamValue::DoubleArray(_), ParamValue::IntegerArray(a)) => {
            ParamValue::DoubleArray(a.into_iter().map(|i| i as f64).collect())
        }
        // An empty YAML list has no element type.
        (d, ParamValue::StringArray(a)) if a.is_empty() => match d {
            ParamValue::DoubleArray(_) => ParamValue::DoubleArray(vec![]),
            ParamValue::IntegerArray(_) => ParamValue::IntegerArray(vec![]),
            ParamValue::BoolArray(_) => ParamValue::BoolArray(vec![]),
            _ => ParamValue::StringArray(vec![]),
        },
        (d, v) if d.type_name() == v.type_name() => v,
        (d, v) => return Err(wrong(name, d.type_name(), &v)),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn yaml_values_become_ros_types() {
        assert_eq!(ParamValue::parse("0.07").unwrap(), ParamValue::Double(0.07));
        assert_eq!(ParamValue::parse("3").unwrap(), ParamValue::Integer(3));
        assert_eq!(ParamValue::parse("true").unwrap(), ParamValue::Bool(true));
        assert_eq!(ParamValue::parse("vertical").unwrap(), ParamValue::String("vertical".into()));
        assert_eq!(
            ParamValue::parse("[cam1, cam2]").unwrap(),
            ParamValue::StringArray(vec!["cam1".into(), "cam2".into()])
        );
        assert_eq!(ParamValue::parse("[0, 1.0, 0, 0]").unwrap(), ParamValue::DoubleArray(vec![0.0, 1.0, 0.0, 0.0]));
        assert!(ParamValue::parse("[1, a]").is_err());
        assert!(ParamValue::parse("{a: 1}").is_err());
    }

    #[test]
    fn resolve_coerces_and_refuses_wrong_types() {
        let decls = [
            ParamDecl { name: "speed", default: ParamValue::Double(0.07), unit: "m/s", description: "" },
            ParamDecl { name: "plane", default: ParamValue::DoubleArray(vec![0.0; 4]), unit: "", description: "" },
        ];
        let mut o = BTreeMap::new();
        o.insert("speed".to_string(), ParamValue::Integer(1));
        o.insert("plane".to_string(), ParamValue::IntegerArray(vec![0, 1, 0, 0]));
        let p = Params::resolve(&decls, &o).unwrap();
        assert_eq!(p.f64("speed").unwrap(), 1.0);
        assert_eq!(p.f64_array("plane").unwrap(), vec![0.0, 1.0, 0.0, 0.0]);
        o.insert("speed".to_string(), ParamValue::String("fast".into()));
        let e = Params::resolve(&decls, &o).unwrap_err();
        assert!(e.to_string().contains("parameter speed: expected double, got string"), "{e}");
        let mut p = p;
        assert!(matches!(p.set(&decls, "nope", ParamValue::Bool(true)), Err(ParamError::Undeclared(_))));
    }
}
