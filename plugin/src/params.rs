//! Parameter values at a time, read through the parameter suite into the core's
//! [`ParamValues`], typed by the registry's [`ParamKind`].
//!
//! Choices are read as option indices; a [`ParamKind::Matrix`] lives in a single-line string
//! parameter holding 16 numbers, row-major ([`nerfx_graph::matrix_text`], [`nerfx_graph::parse_matrix`]). The core then
//! validates every value (ranges, finiteness) with errors naming node and parameter.

use std::ffi::CStr;
use std::os::raw::{c_char, c_int};

use nerfx_core::Error;
use nerfx_graph::{parse_matrix, Node, ParamKind, ParamValues, Value};
use openfx_sys::OfxParamHandle;

use crate::instance::Instance;
use crate::status::{check, Failure, Result};
use crate::suites::suites;

/// Reads one value of `kind` from `handle` at `time`.
///
/// # Safety
/// `handle` must be a live parameter handle of the type [`crate::param_defs`] defined for
/// `kind`.
unsafe fn read(handle: OfxParamHandle, kind: &ParamKind, time: f64) -> Result<Value, String> {
    let get = suites()
        .map_err(|f| f.message)?
        .param
        .paramGetValueAtTime
        .ok_or("the host's parameter suite has no paramGetValueAtTime")?;
    let status = |s| check("paramGetValueAtTime", s).map_err(|f: Failure| f.message);
    // SAFETY (all calls): the variadic arguments are the pointers ofxParam.h lists for the
    // parameter's type, each to storage of that type.
    unsafe {
        Ok(match kind {
            ParamKind::Double { .. } => {
                let mut v = 0.0f64;
                status(get(handle, time, &mut v as *mut f64))?;
                Value::Double(v)
            }
            ParamKind::Int { .. } | ParamKind::Bool { .. } | ParamKind::Choice { .. } => {
                let mut v: c_int = 0;
                status(get(handle, time, &mut v as *mut c_int))?;
                match kind {
                    ParamKind::Int { .. } => Value::Int(v.into()),
                    ParamKind::Bool { .. } => Value::Bool(v != 0),
                    _ => Value::Choice(
                        usize::try_from(v).map_err(|_| format!("option {v} does not exist"))?,
                    ),
                }
            }
            ParamKind::File | ParamKind::Text { .. } | ParamKind::Matrix { .. } => {
                let mut v: *mut c_char = std::ptr::null_mut();
                status(get(handle, time, &mut v as *mut *mut c_char))?;
                let text = if v.is_null() {
                    String::new()
                } else {
                    CStr::from_ptr(v)
                        .to_str()
                        .map_err(|_| "the text is not UTF-8".to_string())?
                        .to_string()
                };
                match kind {
                    ParamKind::Matrix { .. } => Value::Doubles(parse_matrix(&text)?.to_vec()),
                    _ => Value::Text(text),
                }
            }
            ParamKind::Rgb { .. } | ParamKind::Double3 { .. } => {
                let mut v = [0.0f64; 3];
                let [a, b, c] = v.each_mut().map(|p| p as *mut f64);
                status(get(handle, time, a, b, c))?;
                Value::Doubles(v.to_vec())
            }
            ParamKind::Rgba { .. } => {
                let mut v = [0.0f64; 4];
                let [a, b, c, d] = v.each_mut().map(|p| p as *mut f64);
                status(get(handle, time, a, b, c, d))?;
                Value::Doubles(v.to_vec())
            }
        })
    }
}

/// Every parameter of the instance's node at `time`, validated by the core.
pub fn values_at(instance: &Instance, time: f64) -> Result<ParamValues> {
    let desc = &instance.node.desc;
    let mut values = instance.node.defaults();
    for (p, handle) in desc.params.iter().zip(&instance.params) {
        // SAFETY: the handles were fetched at createInstance for these parameters.
        let value = unsafe { read(handle.0, &p.kind, time) }.map_err(|why| {
            Failure::from(Error::invalid(
                format!("{}: parameter {}", desc.id, p.name),
                why,
            ))
        })?;
        values.set(p.name, value)?;
    }
    Ok(values)
}

/// The first file parameter of the node still empty in `values`: the node is not ready.
pub fn unset_file(node: &Node, values: &ParamValues) -> Option<&'static str> {
    node.desc
        .params
        .iter()
        .filter(|p| matches!(p.kind, ParamKind::File))
        .find(|p| values.text(p.name).is_ok_and(str::is_empty))
        .map(|p| p.name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_node_with_an_empty_file_is_not_ready() {
        let node = nerfx_graph::node("org.nerfx.NeRFRender").unwrap();
        let files: Vec<&str> = node
            .desc
            .params
            .iter()
            .filter(|p| matches!(p.kind, ParamKind::File))
            .map(|p| p.name)
            .collect();
        assert!(!files.is_empty());
        let mut values = node.defaults();
        // Defaults: every file empty; the first one is named.
        assert_eq!(unset_file(node, &values), Some(files[0]));
        for (i, f) in files.iter().enumerate() {
            values
                .set(f, nerfx_graph::Value::Text(format!("/x/{i}.json")))
                .unwrap();
        }
        assert_eq!(unset_file(node, &values), None);
        // Nodes without files are always ready.
        for n in nerfx_graph::nodes() {
            if !n
                .desc
                .params
                .iter()
                .any(|p| matches!(p.kind, ParamKind::File))
            {
                assert_eq!(unset_file(n, &n.defaults()), None, "{}", n.desc.id);
            }
        }
    }
}
