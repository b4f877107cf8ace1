//! Parameter descriptors from the registry's [`ParamDesc`]s.
//!
//! Types: Double → double, Int → integer, Bool → boolean, Choice → choice (options are the
//! labels, in order; the value is the index), File → string in file-path mode that must
//! exist and never animates, Text → single-line string, Rgb/Rgba → RGB/RGBA, Double3 →
//! double3D, Matrix → single-line string of 16 numbers, row-major (OpenFX has no matrix
//! type; see [`nerfx_graph::parse_matrix`]). Every parameter gets its label, hint,
//! default, ranges, animation flag and evaluate-on-change.

use nerfx_graph::{matrix_text, ParamDesc, ParamKind, Range};
use openfx_sys::*;

use crate::props::{name, optional, Props};
use crate::status::{check, Failure, Result};
use crate::suites::suites;

/// The OpenFX parameter type for `kind`.
pub fn param_type(kind: &ParamKind) -> &'static [u8] {
    match kind {
        ParamKind::Double { .. } => kOfxParamTypeDouble,
        ParamKind::Int { .. } => kOfxParamTypeInteger,
        ParamKind::Bool { .. } => kOfxParamTypeBoolean,
        ParamKind::Choice { .. } => kOfxParamTypeChoice,
        ParamKind::File | ParamKind::Text { .. } | ParamKind::Matrix { .. } => kOfxParamTypeString,
        ParamKind::Rgb { .. } => kOfxParamTypeRGB,
        ParamKind::Rgba { .. } => kOfxParamTypeRGBA,
        ParamKind::Double3 { .. } => kOfxParamTypeDouble3D,
    }
}

/// The hint shown for `p` (a matrix's says how to type it).
pub fn hint(p: &ParamDesc) -> String {
    match p.kind {
        ParamKind::Matrix { .. } => format!(
            "{} Typed as 16 numbers, row-major (row 1, then row 2, …), separated by spaces or \
             commas.",
            p.hint
        ),
        _ => p.hint.to_string(),
    }
}

/// An integer range bound, saturated to `int`.
fn int_bound(v: f64) -> i32 {
    v.clamp(f64::from(i32::MIN), f64::from(i32::MAX)).round() as i32
}

fn set_range(p: Props, r: &Range, n: usize) -> Result<()> {
    p.set_doubles(name(kOfxParamPropMin), &vec![r.min; n])?;
    p.set_doubles(name(kOfxParamPropMax), &vec![r.max; n])?;
    optional(p.set_doubles(name(kOfxParamPropDisplayMin), &vec![r.display_min; n]));
    optional(p.set_doubles(name(kOfxParamPropDisplayMax), &vec![r.display_max; n]));
    Ok(())
}

/// Defines `param` in the descriptor's parameter set.
pub fn define_param(set: OfxParamSetHandle, param: &ParamDesc) -> Result<()> {
    let s = suites()?;
    let define = s
        .param
        .paramDefine
        .ok_or_else(|| Failure::missing_suite("parameter suite's paramDefine"))?;
    let c = std::ffi::CString::new(param.name)
        .map_err(|_| Failure::failed("parameter name with NUL"))?;
    let mut props: OfxPropertySetHandle = std::ptr::null_mut();
    // SAFETY: the descriptor's parameter set, a type constant, a C string, an out pointer.
    let status = unsafe {
        define(
            set,
            name(param_type(&param.kind)).as_ptr(),
            c.as_ptr(),
            &mut props,
        )
    };
    check(format_args!("paramDefine({})", param.name), status)?;
    // SAFETY: the parameter descriptor lives as long as the effect descriptor.
    let p = unsafe { Props::new(props, s.property) };
    p.set_string(name(kOfxPropLabel), param.label)?;
    optional(p.set_string(name(kOfxParamPropHint), &hint(param)));
    let animates = param.animates && !matches!(param.kind, ParamKind::File);
    p.set_int(name(kOfxParamPropAnimates), i32::from(animates))?;
    optional(p.set_int(name(kOfxParamPropEvaluateOnChange), 1));
    let mode =
        |m: &'static [u8]| p.set_string(name(kOfxParamPropStringMode), &name(m).to_string_lossy());
    match &param.kind {
        ParamKind::Double { default, range } => {
            p.set_double(name(kOfxParamPropDefault), *default)?;
            set_range(p, range, 1)?;
        }
        ParamKind::Int { default, range } => {
            p.set_int(name(kOfxParamPropDefault), int_bound(*default as f64))?;
            p.set_int(name(kOfxParamPropMin), int_bound(range.min))?;
            p.set_int(name(kOfxParamPropMax), int_bound(range.max))?;
            optional(p.set_int(name(kOfxParamPropDisplayMin), int_bound(range.display_min)));
            optional(p.set_int(name(kOfxParamPropDisplayMax), int_bound(range.display_max)));
        }
        ParamKind::Bool { default } => {
            p.set_int(name(kOfxParamPropDefault), i32::from(*default))?
        }
        ParamKind::Choice { options, default } => {
            let labels: Vec<&str> = options.iter().map(|o| o.1).collect();
            p.set_strings(name(kOfxParamPropChoiceOption), &labels)?;
            p.set_int(name(kOfxParamPropDefault), int_bound(*default as f64))?;
        }
        ParamKind::File => {
            mode(kOfxParamStringIsFilePath)?;
            optional(p.set_int(name(kOfxParamPropStringFilePathExists), 1));
            p.set_string(name(kOfxParamPropDefault), "")?;
        }
        ParamKind::Text { default } => {
            mode(kOfxParamStringIsSingleLine)?;
            p.set_string(name(kOfxParamPropDefault), default)?;
        }
        ParamKind::Matrix { default } => {
            mode(kOfxParamStringIsSingleLine)?;
            p.set_string(name(kOfxParamPropDefault), &matrix_text(default))?;
        }
        ParamKind::Rgb { default, range } | ParamKind::Double3 { default, range } => {
            p.set_doubles(name(kOfxParamPropDefault), default)?;
            set_range(p, range, 3)?;
        }
        ParamKind::Rgba { default, range } => {
            p.set_doubles(name(kOfxParamPropDefault), default)?;
            set_range(p, range, 4)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_registry_parameter_has_a_type_and_matrices_say_row_major() {
        for node in nerfx_graph::nodes() {
            for p in &node.desc.params {
                let t = name(param_type(&p.kind)).to_str().unwrap();
                assert!(t.starts_with("OfxParamType"), "{}: {t}", p.name);
                if matches!(p.kind, ParamKind::Matrix { .. }) {
                    assert_eq!(t, "OfxParamTypeString");
                    assert!(hint(p).contains("16 numbers, row-major"));
                }
            }
        }
        assert_eq!(int_bound(1e12), i32::MAX);
        assert_eq!(int_bound(-1e6), -1_000_000);
    }
}
