//! Parameter values at a time, read through the parameter suite into the core's
//! [`ParamValues`], typed by the registry's [`ParamKind`].
//!
//! Choices are read as option indices; a [`ParamKind::Matrix`] lives in a single-line string
//! parameter holding 16 numbers, row-major ([`matrix_text`], [`parse_matrix`]). The core then
//! validates every value (ranges, finiteness) with errors naming node and parameter.

use std::ffi::CStr;
use std::os::raw::{c_char, c_int};

use nerfx::graph::{ParamKind, ParamValues, Value};
use nerfx::Error;
use openfx_sys::OfxParamHandle;

use crate::instance::Instance;
use crate::status::{check, Failure, Result};
use crate::suites::suites;

/// How a matrix default is shown: rows separated by commas, e.g.
/// `1 0 0 0, 0 1 0 0, 0 0 1 0, 0 0 0 1`.
pub fn matrix_text(m: &[f64; 16]) -> String {
    m.chunks(4)
        .map(|row| {
            row.iter()
                .map(|v| v.to_string())
                .collect::<Vec<_>>()
                .join(" ")
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// The 16 finite numbers of a matrix string, row-major. Separators are white space, commas,
/// semicolons and brackets, so a pasted Python or NumPy list also reads.
pub fn parse_matrix(text: &str) -> Result<[f64; 16], String> {
    let tokens: Vec<&str> = text
        .split(|c: char| c.is_whitespace() || ",;[]()".contains(c))
        .filter(|t| !t.is_empty())
        .collect();
    if tokens.len() != 16 {
        return Err(format!(
            "expected 16 numbers (a 4×4 matrix, row-major), got {} in {text:?}",
            tokens.len()
        ));
    }
    let mut m = [0.0; 16];
    for (i, (slot, t)) in m.iter_mut().zip(&tokens).enumerate() {
        let v: f64 = t
            .parse()
            .map_err(|_| format!("entry {i} ({t:?}) is not a number"))?;
        if !v.is_finite() {
            return Err(format!("entry {i} ({t:?}) is not finite"));
        }
        *slot = v;
    }
    Ok(m)
}

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matrices_read_row_major_with_any_separator() {
        let m = parse_matrix("1 2 3 4, 5 6 7 8; [9 10 11 12] (13,14,15,-1.5e2)").unwrap();
        let want: Vec<f64> = (1..=15).map(f64::from).chain([-150.0]).collect();
        assert_eq!(m.to_vec(), want);
    }

    #[test]
    fn matrix_text_reads_back() {
        let m = [
            0.5, -2.0, 0.0, 1e-7, 0.1, 1.0, 3.25, 10.0, 0.0, 0.0, 1.0, -4.5, 0.0, 0.0, 0.0, 1.0,
        ];
        assert_eq!(
            matrix_text(&[
                1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0
            ]),
            "1 0 0 0, 0 1 0 0, 0 0 1 0, 0 0 0 1"
        );
        assert_eq!(parse_matrix(&matrix_text(&m)).unwrap(), m);
    }

    #[test]
    fn bad_matrices_say_why() {
        let e = parse_matrix("1 0 0 0 0 1 0 0 0 0 1 0 0 0 0").unwrap_err();
        assert!(
            e.contains("expected 16 numbers") && e.contains("got 15"),
            "{e}"
        );
        let e = parse_matrix("1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 x").unwrap_err();
        assert!(e.contains("entry 15") && e.contains("not a number"), "{e}");
        let e = parse_matrix("1 0 0 0 0 NaN 0 0 0 0 1 0 0 0 0 1").unwrap_err();
        assert!(e.contains("entry 5") && e.contains("not finite"), "{e}");
        assert!(parse_matrix("").is_err());
    }
}
