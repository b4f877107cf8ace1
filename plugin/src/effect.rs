//! The image effect handle of an action, descriptor or instance: its property set, its
//! parameter set, and the OpenFX names of the contexts it is described or created in.

use nerfx_graph::Context;
use openfx_sys::*;

use crate::props::{name, Props};
use crate::status::{check, Failure, Result, ERR_UNSUPPORTED};
use crate::suites::suites;

/// The effect's property set.
pub fn effect_props(effect: OfxImageEffectHandle) -> Result<Props> {
    let s = suites()?;
    let get = s
        .effect
        .getPropertySet
        .ok_or_else(|| Failure::missing_suite("image effect suite's getPropertySet"))?;
    let mut set: OfxPropertySetHandle = std::ptr::null_mut();
    // SAFETY: `effect` is the handle of the current action; `set` receives a handle.
    check("getPropertySet", unsafe { get(effect, &mut set) })?;
    // SAFETY: the property set lives as long as the effect.
    Ok(unsafe { Props::new(set, s.property) })
}

/// The effect's parameter set (of a descriptor or an instance).
pub fn param_set(effect: OfxImageEffectHandle) -> Result<OfxParamSetHandle> {
    let get = suites()?
        .effect
        .getParamSet
        .ok_or_else(|| Failure::missing_suite("image effect suite's getParamSet"))?;
    let mut set: OfxParamSetHandle = std::ptr::null_mut();
    // SAFETY: `effect` is the handle of the current action; `set` receives a handle.
    check("getParamSet", unsafe { get(effect, &mut set) })?;
    Ok(set)
}

/// The OpenFX name of `context`.
pub fn context_name(context: Context) -> &'static [u8] {
    match context {
        Context::Generator => kOfxImageEffectContextGenerator,
        Context::Filter => kOfxImageEffectContextFilter,
        Context::General => kOfxImageEffectContextGeneral,
    }
}

/// The context named `text`; other contexts are unsupported.
pub fn context_from_name(text: &str) -> Result<Context> {
    [Context::Generator, Context::Filter, Context::General]
        .into_iter()
        .find(|c| name(context_name(*c)).to_bytes() == text.as_bytes())
        .ok_or_else(|| Failure {
            status: ERR_UNSUPPORTED,
            message: format!("context {text:?} is not supported"),
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn context_names_round_trip() {
        for c in [Context::Generator, Context::Filter, Context::General] {
            let text = name(context_name(c)).to_str().unwrap();
            assert_eq!(context_from_name(text).unwrap(), c);
        }
        assert_eq!(
            context_from_name("OfxImageEffectContextFilter").unwrap(),
            Context::Filter
        );
        let e = context_from_name("OfxImageEffectContextPaint").unwrap_err();
        assert_eq!(e.status, ERR_UNSUPPORTED);
    }
}
