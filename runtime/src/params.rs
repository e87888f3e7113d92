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
    /// The closed interval a number must lie in, if the declaration bounds it (checked when
    /// the parameters are read, at start-up and at every run-time set).
    pub range: Option<(f64, f64)>,
}

impl ParamDecl {
    /// A declaration without a range.
    pub fn new(name: &'static str, default: ParamValue, unit: &'static str, description: &'static str) -> ParamDecl {
        ParamDecl { name, default, unit, description, range: None }
    }
    /// The range as the docs show it (`[0, 600]`), or "".
    pub fn range_text(&self) -> String {
        self.range.map(|(lo, hi)| format!("[{lo}, {hi}]")).unwrap_or_default()
    }
    /// The line of a node's `--help`: `name (type, in [lo, hi], default D unit): meaning`.
    pub fn help_line(&self) -> String {
        let unit = if self.unit.is_empty() { String::new() } else { format!(" {}", self.unit) };
        let range = self.range.map(|_| format!(", in {}", self.range_text())).unwrap_or_default();
        format!(
            "{} ({}{range}, default {}{unit}): {}",
            self.name,
            self.default.type_name(),
            self.default,
            self.description
        )
    }
    /// The row of the node docs' parameter table (see [`markdown_table`]).
    pub fn markdown_row(&self) -> String {
        format!(
            "| `{}` | {} | `{}` | {} | {} | {} |",
            self.name,
            self.default.type_name(),
            self.default,
            self.unit,
            self.range_text(),
            self.description
        )
    }
}

/// The parameter table of a node's docs (nodes/README.md), from its declarations.
pub fn markdown_table(decls: &[ParamDecl]) -> String {
    let mut s = String::from("| parameter | type | default | unit | range | meaning |\n|---|---|---|---|---|---|\n");
    for d in decls {
        s.push_str(&d.markdown_row());
        s.push('\n');
    }
    s
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
                Some(d) => checked(d, v.clone())?,
                None => v.clone(),
            };
            values.insert(name.clone(), v);
        }
        Ok(Params { values })
    }
    /// Sets one value at run time, checked against the declaration's type.
    pub fn set(&mut self, decls: &[ParamDecl], name: &str, v: ParamValue) -> Result<(), ParamError> {
        let d = decls.iter().find(|d| d.name == name).ok_or_else(|| ParamError::Undeclared(name.into()))?;
        let v = checked(d, v)?;
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

/// `v` in the declaration's type and range.
fn checked(d: &ParamDecl, v: ParamValue) -> Result<ParamValue, ParamError> {
    let v = coerce(d.name, &d.default, v)?;
    let x = match v {
        ParamValue::Double(x) => x,
        ParamValue::Integer(i) => i as f64,
        _ => return Ok(v),
    };
    if let Some((lo, hi)) = d.range {
        if !(lo..=hi).contains(&x) {
            let unit = if d.unit.is_empty() { String::new() } else { format!(" {}", d.unit) };
            return Err(Params::invalid(d.name, format!("{v}{unit} is not in [{lo}, {hi}]")));
        }
    } else if !x.is_finite() {
        return Err(Params::invalid(d.name, format!("{v} is not a finite number")));
    }
    Ok(v)
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

/// A Rust type a parameter is read into, and the ROS 2 value it is declared with.
pub trait ParamType: Sized {
    /// The ROS 2 value of `self` (a declaration's default).
    fn to_value(&self) -> ParamValue;
    /// The value of `name` in `p`.
    fn read(p: &Params, name: &str) -> Result<Self, ParamError>;
}

impl ParamType for bool {
    fn to_value(&self) -> ParamValue {
        ParamValue::Bool(*self)
    }
    fn read(p: &Params, name: &str) -> Result<Self, ParamError> {
        p.bool(name)
    }
}

impl ParamType for i64 {
    fn to_value(&self) -> ParamValue {
        ParamValue::Integer(*self)
    }
    fn read(p: &Params, name: &str) -> Result<Self, ParamError> {
        p.i64(name)
    }
}

macro_rules! unsigned_param {
    ($($t:ty),*) => {$(
        impl ParamType for $t {
            fn to_value(&self) -> ParamValue {
                ParamValue::Integer(i64::try_from(*self).unwrap_or(i64::MAX))
            }
            fn read(p: &Params, name: &str) -> Result<Self, ParamError> {
                let v = p.i64(name)?;
                <$t>::try_from(v).map_err(|_| Params::invalid(name, format!("{v} is not in 0..={}", <$t>::MAX)))
            }
        }
    )*};
}
unsigned_param!(u32, usize);

impl ParamType for f64 {
    fn to_value(&self) -> ParamValue {
        ParamValue::Double(*self)
    }
    fn read(p: &Params, name: &str) -> Result<Self, ParamError> {
        p.f64(name)
    }
}

impl ParamType for f32 {
    /// As written (`0.012`), not as the binary value widens.
    fn to_value(&self) -> ParamValue {
        ParamValue::from_f32(*self)
    }
    fn read(p: &Params, name: &str) -> Result<Self, ParamError> {
        let v = p.f64(name)?;
        let x = v as f32;
        if v.is_finite() && !x.is_finite() {
            return Err(Params::invalid(name, format!("{v:?} is beyond the range of a 32-bit float")));
        }
        Ok(x)
    }
}

impl ParamType for String {
    fn to_value(&self) -> ParamValue {
        ParamValue::String(self.clone())
    }
    fn read(p: &Params, name: &str) -> Result<Self, ParamError> {
        p.string(name)
    }
}

/// A path, or none: the empty string.
impl ParamType for Option<std::path::PathBuf> {
    fn to_value(&self) -> ParamValue {
        ParamValue::String(self.as_ref().map(|p| p.display().to_string()).unwrap_or_default())
    }
    fn read(p: &Params, name: &str) -> Result<Self, ParamError> {
        let s = p.string(name)?;
        Ok((!s.is_empty()).then(|| std::path::PathBuf::from(s)))
    }
}

impl ParamType for Vec<f64> {
    fn to_value(&self) -> ParamValue {
        ParamValue::DoubleArray(self.clone())
    }
    fn read(p: &Params, name: &str) -> Result<Self, ParamError> {
        let v = p.f64_array(name)?;
        if let Some(x) = v.iter().find(|x| !x.is_finite()) {
            return Err(Params::invalid(name, format!("{x} is not a finite number")));
        }
        Ok(v)
    }
}

impl ParamType for Vec<String> {
    fn to_value(&self) -> ParamValue {
        ParamValue::StringArray(self.clone())
    }
    fn read(p: &Params, name: &str) -> Result<Self, ParamError> {
        p.string_array(name)
    }
}

/// How a field of a [`parameters!`](crate::parameters) struct is converted: [`Plain`] for the
/// types of [`ParamType`], [`Choice`] for a set of named values.
pub trait ParamConv<T> {
    /// The ROS 2 value of `t`.
    fn to_value(t: &T) -> ParamValue;
    /// The value of `name` in `p`.
    fn read(p: &Params, name: &str) -> Result<T, ParamError>;
}

/// The conversion of a [`ParamType`].
pub struct Plain;

impl<T: ParamType> ParamConv<T> for Plain {
    fn to_value(t: &T) -> ParamValue {
        t.to_value()
    }
    fn read(p: &Params, name: &str) -> Result<T, ParamError> {
        T::read(p, name)
    }
}

/// A string parameter naming one of a set of values (an enum): written by `Display`, read by
/// `FromStr`, whose error says what the choices are.
pub struct Choice;

impl<T: std::str::FromStr<Err = String> + fmt::Display> ParamConv<T> for Choice {
    fn to_value(t: &T) -> ParamValue {
        ParamValue::String(t.to_string())
    }
    fn read(p: &Params, name: &str) -> Result<T, ParamError> {
        p.string(name)?.parse().map_err(|e| Params::invalid(name, e))
    }
}

/// A node's parameters as one typed struct: what [`parameters!`](crate::parameters) derives.
pub trait NodeParams: Sized {
    /// The declarations: names, defaults, units, ranges and meanings.
    fn declarations() -> Vec<ParamDecl>;
    /// The typed values from resolved parameters.
    fn from_params(p: &Params) -> Result<Self, ParamError>;
}

/// Declares a node's parameters once: a struct whose fields carry each parameter's meaning
/// (the field's doc comment), default, unit and range, and from which come the declarations
/// (for the ROS 2 parameter services, `--help` and the node docs), the typed values, and their
/// check at start-up and at every run-time set, as `generate_parameter_library` does for C++
/// nodes.
///
/// ```
/// xsurf_runtime::parameters! {
///     /// The parameters of a node.
///     pub struct Example {
///         /// travel speed
///         speed: f64 = 0.07, unit "m/s", range 0.0..=2.0;
///         /// first column searched
///         roi_x_offset ["roi.x_offset"]: u32 = 0, unit "px";
///     }
/// }
/// use xsurf_runtime::params::{NodeParams, Params};
/// let p = Params::resolve(&Example::declarations(), &Default::default()).unwrap();
/// assert_eq!(Example::from_params(&p).unwrap(), Example::default());
/// assert_eq!(Example::declarations()[1].name, "roi.x_offset");
/// ```
///
/// A field is `name ["ros.name"]: Type = default`, then optionally `, unit "..."`,
/// `, range lo..=hi` (a closed interval, for numbers) and `, via Choice` (an enum read by
/// `FromStr` and written by `Display`); the ROS name defaults to the field's name.
#[macro_export]
macro_rules! parameters {
    (
        $(#[$meta:meta])*
        $vis:vis struct $name:ident {
            $(
                $(#[doc = $doc:literal])+
                $field:ident $([$ros:literal])? : $ty:ty = $default:expr
                    $(, unit $unit:literal)?
                    $(, range $lo:literal ..= $hi:literal)?
                    $(, via $conv:ident)?
                ;
            )*
        }
    ) => {
        $(#[$meta])*
        #[derive(Debug, Clone, PartialEq)]
        $vis struct $name {
            $(
                $(#[doc = $doc])+
                pub $field: $ty,
            )*
        }

        impl ::std::default::Default for $name {
            fn default() -> Self {
                Self { $($field: $default,)* }
            }
        }

        impl $crate::params::NodeParams for $name {
            fn declarations() -> ::std::vec::Vec<$crate::params::ParamDecl> {
                ::std::vec![$(
                    $crate::params::ParamDecl {
                        name: $crate::parameters!(@name $field $($ros)?),
                        default: <$crate::parameters!(@conv $($conv)?) as $crate::params::ParamConv<$ty>>::to_value(
                            &$default,
                        ),
                        unit: $crate::parameters!(@unit $($unit)?),
                        description: concat!($($doc),+).trim_ascii(),
                        range: $crate::parameters!(@range $($lo, $hi)?),
                    },
                )*]
            }
            fn from_params(
                p: &$crate::params::Params,
            ) -> ::std::result::Result<Self, $crate::params::ParamError> {
                Ok(Self {$(
                    $field: <$crate::parameters!(@conv $($conv)?) as $crate::params::ParamConv<$ty>>::read(
                        p,
                        $crate::parameters!(@name $field $($ros)?),
                    )?,
                )*})
            }
        }
    };
    (@name $field:ident) => { stringify!($field) };
    (@name $field:ident $ros:literal) => { $ros };
    (@conv) => { $crate::params::Plain };
    (@conv $conv:ident) => { $crate::params::$conv };
    (@unit) => { "" };
    (@unit $unit:literal) => { $unit };
    (@range) => { None };
    (@range $lo:literal, $hi:literal) => { Some(($lo as f64, $hi as f64)) };
}

/// An enum whose values a string parameter names (read with `via Choice` in
/// [`parameters!`](crate::parameters)): `Display` writes the name, `FromStr` reads it and
/// otherwise says what the choices are.
///
/// ```
/// xsurf_runtime::choice! {
///     /// Where the travel comes from.
///     pub enum Mode {
///         /// The speed model.
///         Speed = "speed",
///         /// The controller's feed.
///         Encoder = "encoder",
///     }
/// }
/// assert_eq!("encoder".parse::<Mode>(), Ok(Mode::Encoder));
/// assert_eq!("x".parse::<Mode>().unwrap_err(), "\"x\": expected speed or encoder");
/// assert_eq!(Mode::Speed.to_string(), "speed");
/// ```
#[macro_export]
macro_rules! choice {
    (
        $(#[$meta:meta])*
        $vis:vis enum $name:ident {
            $( $(#[$vmeta:meta])* $variant:ident = $text:literal ),+ $(,)?
        }
    ) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq)]
        $vis enum $name { $( $(#[$vmeta])* $variant ),+ }

        impl $name {
            /// Every value's name, in declaration order.
            pub const NAMES: &'static [&'static str] = &[$($text),+];
        }

        impl ::std::fmt::Display for $name {
            fn fmt(&self, f: &mut ::std::fmt::Formatter<'_>) -> ::std::fmt::Result {
                f.write_str(match self { $( $name::$variant => $text ),+ })
            }
        }

        impl ::std::str::FromStr for $name {
            type Err = ::std::string::String;
            fn from_str(s: &str) -> ::std::result::Result<Self, ::std::string::String> {
                match s {
                    $( $text => Ok($name::$variant), )+
                    other => Err(format!("{other:?}: expected {}", $crate::params::one_of(Self::NAMES))),
                }
            }
        }
    };
}

/// `a, b or c`.
pub fn one_of(names: &[&str]) -> String {
    match names {
        [] => String::new(),
        [one] => (*one).to_string(),
        [rest @ .., last] => format!("{} or {last}", rest.join(", ")),
    }
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
            ParamDecl::new("speed", ParamValue::Double(0.07), "m/s", ""),
            ParamDecl::new("plane", ParamValue::DoubleArray(vec![0.0; 4]), "", ""),
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

    #[derive(Debug, Clone, Copy, PartialEq)]
    enum Shape {
        Flat,
        Round,
    }
    impl fmt::Display for Shape {
        fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
            f.write_str(match self {
                Shape::Flat => "flat",
                Shape::Round => "round",
            })
        }
    }
    impl std::str::FromStr for Shape {
        type Err = String;
        fn from_str(s: &str) -> Result<Self, String> {
            match s {
                "flat" => Ok(Shape::Flat),
                "round" => Ok(Shape::Round),
                other => Err(format!("{other:?} is not flat or round")),
            }
        }
    }

    crate::parameters! {
        /// Test parameters.
        struct Test {
            /// travel speed,
            /// over two lines
            speed: f64 = 0.07, unit "m/s", range 0.0..=2.0;
            /// a width
            width: f32 = 0.012, unit "m";
            /// first column
            roi_x ["roi.x_offset"]: u32 = 0, unit "px";
            /// shape
            shape: Shape = Shape::Round, via Choice;
            /// where to write
            out: Option<std::path::PathBuf> = None;
            /// cameras
            cameras: Vec<String> = vec!["cam1".into()];
        }
    }

    #[test]
    fn one_declaration_gives_declarations_values_and_checks() {
        let decls = Test::declarations();
        let names: Vec<_> = decls.iter().map(|d| d.name).collect();
        assert_eq!(names, ["speed", "width", "roi.x_offset", "shape", "out", "cameras"]);
        assert_eq!(decls[0].description, "travel speed, over two lines");
        assert_eq!((decls[0].unit, decls[0].range), ("m/s", Some((0.0, 2.0))));
        assert_eq!(decls[1].default.to_string(), "0.012");
        assert_eq!(decls[3].default, ParamValue::String("round".into()));
        assert_eq!(decls[4].default, ParamValue::String(String::new()));
        let p = Params::resolve(&decls, &BTreeMap::new()).unwrap();
        assert_eq!(Test::from_params(&p).unwrap(), Test::default());

        let mut o = BTreeMap::new();
        o.insert("shape".to_string(), ParamValue::String("flat".into()));
        o.insert("out".to_string(), ParamValue::String("/tmp/x".into()));
        o.insert("roi.x_offset".to_string(), ParamValue::Integer(7));
        let t = Test::from_params(&Params::resolve(&decls, &o).unwrap()).unwrap();
        assert_eq!((t.shape, t.roi_x), (Shape::Flat, 7));
        assert_eq!(t.out.as_deref(), Some(std::path::Path::new("/tmp/x")));

        let refused = |name: &str, v: ParamValue| {
            let mut o = BTreeMap::new();
            o.insert(name.to_string(), v);
            match Params::resolve(&decls, &o) {
                Err(e) => e.to_string(),
                Ok(p) => Test::from_params(&p).unwrap_err().to_string(),
            }
        };
        assert_eq!(refused("speed", ParamValue::Double(2.5)), "parameter speed: 2.5 m/s is not in [0, 2]");
        assert_eq!(refused("width", ParamValue::Double(f64::NAN)), "parameter width: NaN is not a finite number");
        assert_eq!(
            refused("roi.x_offset", ParamValue::Integer(-1)),
            "parameter roi.x_offset: -1 is not in 0..=4294967295"
        );
        assert_eq!(
            refused("shape", ParamValue::String("cube".into())),
            "parameter shape: \"cube\" is not flat or round"
        );
        // A run-time set goes through the same check.
        let mut p = p;
        assert!(p.set(&decls, "speed", ParamValue::Double(-1.0)).is_err());
        assert!(p.set(&decls, "speed", ParamValue::Integer(1)).is_ok());
    }
}
