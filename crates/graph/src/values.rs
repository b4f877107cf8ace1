//! Parameter values, validated against a node's description.
//!
//! Values out of range are **refused, not clamped**: a typo in a graph file must be an
//! error naming the node and parameter rather than a silently different render (OpenFX hosts
//! enforce the same ranges on their side). NaN and ±inf are refused everywhere.

use std::collections::BTreeMap;

use super::desc::{NodeDesc, ParamKind};
use nerfx_core::error::{Error, Result};

/// One parameter value.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// For [`ParamKind::Double`].
    Double(f64),
    /// For [`ParamKind::Int`].
    Int(i64),
    /// For [`ParamKind::Bool`].
    Bool(bool),
    /// For [`ParamKind::Choice`]: the option's index.
    Choice(usize),
    /// For [`ParamKind::File`] and [`ParamKind::Text`].
    Text(String),
    /// For [`ParamKind::Rgb`] (3), [`ParamKind::Rgba`] (4), [`ParamKind::Double3`] (3) and
    /// [`ParamKind::Matrix`] (16, row-major).
    Doubles(Vec<f64>),
}

impl Value {
    fn type_name(&self) -> &'static str {
        match self {
            Value::Double(_) => "a double",
            Value::Int(_) => "an int",
            Value::Bool(_) => "a bool",
            Value::Choice(_) => "a choice",
            Value::Text(_) => "text",
            Value::Doubles(_) => "a list of doubles",
        }
    }
}

/// The values of every parameter of one node, each checked against its description.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamValues {
    desc: &'static NodeDesc,
    values: BTreeMap<&'static str, Value>,
}

fn default_value(kind: &ParamKind) -> Value {
    match kind {
        ParamKind::Double { default, .. } => Value::Double(*default),
        ParamKind::Int { default, .. } => Value::Int(*default),
        ParamKind::Bool { default } => Value::Bool(*default),
        ParamKind::Choice { default, .. } => Value::Choice(*default),
        ParamKind::File => Value::Text(String::new()),
        ParamKind::Text { default } => Value::Text((*default).to_string()),
        ParamKind::Rgb { default, .. } | ParamKind::Double3 { default, .. } => {
            Value::Doubles(default.to_vec())
        }
        ParamKind::Rgba { default, .. } => Value::Doubles(default.to_vec()),
        ParamKind::Matrix { default } => Value::Doubles(default.to_vec()),
    }
}

/// Why `value` does not fit `kind`, if it does not.
fn check(kind: &ParamKind, value: &Value) -> Option<String> {
    let out_of = |v: f64, r: &super::desc::Range| {
        (!r.contains(v)).then(|| format!("{v} is outside [{}, {}]", r.min, r.max))
    };
    let list = |v: &[f64], n: usize, r: Option<&super::desc::Range>| {
        if v.len() != n {
            return Some(format!("expected {n} values, got {}", v.len()));
        }
        match r {
            Some(r) => v.iter().find_map(|&x| out_of(x, r)),
            None => v
                .iter()
                .find(|x| !x.is_finite())
                .map(|x| format!("{x} is not finite")),
        }
    };
    match (kind, value) {
        (ParamKind::Double { range, .. }, Value::Double(v)) => out_of(*v, range),
        (ParamKind::Int { range, .. }, Value::Int(v)) => out_of(*v as f64, range),
        (ParamKind::Bool { .. }, Value::Bool(_)) => None,
        (ParamKind::Choice { options, .. }, Value::Choice(i)) => (*i >= options.len())
            .then(|| format!("option {i} does not exist ({} options)", options.len())),
        (ParamKind::File | ParamKind::Text { .. }, Value::Text(_)) => None,
        (ParamKind::Rgb { range, .. } | ParamKind::Double3 { range, .. }, Value::Doubles(v)) => {
            list(v, 3, Some(range))
        }
        (ParamKind::Rgba { range, .. }, Value::Doubles(v)) => list(v, 4, Some(range)),
        (ParamKind::Matrix { .. }, Value::Doubles(v)) => list(v, 16, None),
        (kind, value) => Some(format!(
            "expected {}, got {}",
            expected(kind),
            value.type_name()
        )),
    }
}

fn expected(kind: &ParamKind) -> &'static str {
    match kind {
        ParamKind::Double { .. } => "a double",
        ParamKind::Int { .. } => "an int",
        ParamKind::Bool { .. } => "a bool",
        ParamKind::Choice { .. } => "a choice",
        ParamKind::File => "a file path (text)",
        ParamKind::Text { .. } => "text",
        ParamKind::Rgb { .. } => "an RGB colour (3 doubles)",
        ParamKind::Rgba { .. } => "an RGBA colour (4 doubles)",
        ParamKind::Double3 { .. } => "3 doubles",
        ParamKind::Matrix { .. } => "a 4×4 matrix (16 doubles, row-major)",
    }
}

impl ParamValues {
    /// Every parameter of `desc` at its default.
    pub fn defaults(desc: &'static NodeDesc) -> Self {
        let values = desc
            .params
            .iter()
            .map(|p| (p.name, default_value(&p.kind)))
            .collect();
        ParamValues { desc, values }
    }

    /// The node these values belong to.
    pub fn desc(&self) -> &'static NodeDesc {
        self.desc
    }

    fn error(&self, name: &str, message: impl Into<String>) -> Error {
        Error::invalid(format!("{}: parameter {name}", self.desc.id), message)
    }

    /// Sets `name` to `value`; an unknown name, a wrong type or an out-of-range value is
    /// refused with an error naming the node and the parameter.
    pub fn set(&mut self, name: &str, value: Value) -> Result<()> {
        let Some(param) = self.desc.param(name) else {
            let names: Vec<&str> = self.desc.params.iter().map(|p| p.name).collect();
            return Err(self.error(
                name,
                format!("no such parameter (parameters: {})", names.join(", ")),
            ));
        };
        if let Some(why) = check(&param.kind, &value) {
            return Err(self.error(name, why));
        }
        self.values.insert(param.name, value);
        Ok(())
    }

    /// Sets the choice parameter `name` to the option whose identifier is `id`.
    pub fn set_choice(&mut self, name: &str, id: &str) -> Result<()> {
        let options = match self.desc.param(name).map(|p| &p.kind) {
            Some(ParamKind::Choice { options, .. }) => *options,
            _ => return Err(self.error(name, "not a choice")),
        };
        match options.iter().position(|(o, _)| *o == id) {
            Some(i) => self.set(name, Value::Choice(i)),
            None => {
                let ids: Vec<&str> = options.iter().map(|(o, _)| *o).collect();
                Err(self.error(
                    name,
                    format!("no option {id} (options: {})", ids.join(", ")),
                ))
            }
        }
    }

    /// These values with the parameters `names` at their defaults (unknown names are left
    /// alone).
    pub fn with_defaults(&self, names: &[&str]) -> ParamValues {
        let mut values = self.clone();
        for p in self.desc.params.iter().filter(|p| names.contains(&p.name)) {
            values.values.insert(p.name, default_value(&p.kind));
        }
        values
    }

    /// Every parameter with its value, in the description's order.
    pub fn iter(&self) -> impl Iterator<Item = (&'static str, &Value)> + '_ {
        self.desc
            .params
            .iter()
            .filter_map(|p| self.values.get(p.name).map(|v| (p.name, v)))
    }

    /// The value of `name`.
    pub fn get(&self, name: &str) -> Result<&Value> {
        self.values
            .get(name)
            .ok_or_else(|| self.error(name, "no such parameter"))
    }

    fn wrong(&self, name: &str, want: &str) -> Error {
        self.error(name, format!("read as {want}, but it is not"))
    }

    /// A double parameter.
    pub fn double(&self, name: &str) -> Result<f64> {
        match self.get(name)? {
            Value::Double(v) => Ok(*v),
            _ => Err(self.wrong(name, "a double")),
        }
    }

    /// An int parameter.
    pub fn int(&self, name: &str) -> Result<i64> {
        match self.get(name)? {
            Value::Int(v) => Ok(*v),
            _ => Err(self.wrong(name, "an int")),
        }
    }

    /// A bool parameter.
    pub fn bool(&self, name: &str) -> Result<bool> {
        match self.get(name)? {
            Value::Bool(v) => Ok(*v),
            _ => Err(self.wrong(name, "a bool")),
        }
    }

    /// A choice parameter's option identifier.
    pub fn choice(&self, name: &str) -> Result<&'static str> {
        let options = match self.desc.param(name).map(|p| &p.kind) {
            Some(ParamKind::Choice { options, .. }) => *options,
            _ => return Err(self.wrong(name, "a choice")),
        };
        match self.get(name)? {
            Value::Choice(i) => options
                .get(*i)
                .map(|o| o.0)
                .ok_or_else(|| self.wrong(name, "a choice")),
            _ => Err(self.wrong(name, "a choice")),
        }
    }

    /// A file or text parameter.
    pub fn text(&self, name: &str) -> Result<&str> {
        match self.get(name)? {
            Value::Text(v) => Ok(v),
            _ => Err(self.wrong(name, "text")),
        }
    }

    /// A colour, 3-vector or matrix parameter.
    pub fn doubles(&self, name: &str) -> Result<&[f64]> {
        match self.get(name)? {
            Value::Doubles(v) => Ok(v),
            _ => Err(self.wrong(name, "doubles")),
        }
    }
}
