//! Safe wrappers over the property suite.
//!
//! A [`Props`] is a property set handle the host gave for the duration of one action, with
//! typed getters and setters that name the property on failure. Strings are copied out at
//! once (the host owns them only until the next call).

use std::ffi::{c_void, CStr, CString};
use std::os::raw::{c_char, c_int};

use openfx_sys::{OfxPropertySetHandle, OfxPropertySuiteV1};

use crate::status::{check, Failure, Result};

/// A property name from the bindings (`&[u8]` ending in NUL) as a C string.
pub fn name(bytes: &'static [u8]) -> &'static CStr {
    CStr::from_bytes_with_nul(bytes).unwrap_or(c"(bad property name)")
}

/// A C string for `text`, interior NULs replaced (texts go to the host).
pub fn c_string(text: &str) -> CString {
    CString::new(text.replace('\0', " ")).unwrap_or_default()
}

/// Drops the failure of setting a descriptor property an older or stricter host may not know
/// (a description, display ranges, field handling, …): hosts answer an unknown property with
/// an error, and failing `describe` for a nicety would lose the whole plugin there.
pub fn optional(result: Result<()>) {
    if let Err(e) = result {
        eprintln!("nerfx.ofx: ignored: {e}");
    }
}

/// A property set and the suite that reads it.
#[derive(Clone, Copy)]
pub struct Props {
    set: OfxPropertySetHandle,
    suite: &'static OfxPropertySuiteV1,
}

macro_rules! call {
    ($self:ident, $f:ident, $what:expr, $($arg:expr),*) => {{
        let f = $self
            .suite
            .$f
            .ok_or_else(|| Failure::missing_suite(concat!("property suite's ", stringify!($f))))?;
        // SAFETY: `set` is a live handle (see `Props::new`), the arguments follow the
        // suite's signature and point to storage of the announced size.
        let status = unsafe { f($self.set, $($arg),*) };
        check(format_args!("{}({})", stringify!($f), $what.to_string_lossy()), status)
    }};
}

impl Props {
    /// Wraps `set`.
    ///
    /// # Safety
    /// `set` must be a property set handle valid for as long as the result is used.
    pub unsafe fn new(set: OfxPropertySetHandle, suite: &'static OfxPropertySuiteV1) -> Self {
        Props { set, suite }
    }

    /// Sets string `prop` to `value`.
    pub fn set_string(&self, prop: &CStr, value: &str) -> Result<()> {
        self.set_string_at(prop, 0, value)
    }

    /// Sets dimension `index` of string `prop`.
    pub fn set_string_at(&self, prop: &CStr, index: usize, value: &str) -> Result<()> {
        let v = c_string(value);
        call!(
            self,
            propSetString,
            prop,
            prop.as_ptr(),
            index as c_int,
            v.as_ptr()
        )
    }

    /// Sets string `prop` to `values` (its dimension becomes their count).
    pub fn set_strings(&self, prop: &CStr, values: &[&str]) -> Result<()> {
        let owned: Vec<CString> = values.iter().map(|v| c_string(v)).collect();
        let ptrs: Vec<*const c_char> = owned.iter().map(|v| v.as_ptr()).collect();
        call!(
            self,
            propSetStringN,
            prop,
            prop.as_ptr(),
            ptrs.len() as c_int,
            ptrs.as_ptr()
        )
    }

    /// Sets int `prop`.
    pub fn set_int(&self, prop: &CStr, value: i32) -> Result<()> {
        call!(self, propSetInt, prop, prop.as_ptr(), 0, value)
    }

    /// Sets double `prop`.
    pub fn set_double(&self, prop: &CStr, value: f64) -> Result<()> {
        call!(self, propSetDouble, prop, prop.as_ptr(), 0, value)
    }

    /// Sets double `prop` to `values`.
    pub fn set_doubles(&self, prop: &CStr, values: &[f64]) -> Result<()> {
        call!(
            self,
            propSetDoubleN,
            prop,
            prop.as_ptr(),
            values.len() as c_int,
            values.as_ptr()
        )
    }

    /// Sets pointer `prop`.
    pub fn set_pointer(&self, prop: &CStr, value: *mut c_void) -> Result<()> {
        call!(self, propSetPointer, prop, prop.as_ptr(), 0, value)
    }

    /// String `prop`, copied.
    pub fn string(&self, prop: &CStr) -> Result<String> {
        let mut v: *mut c_char = std::ptr::null_mut();
        call!(self, propGetString, prop, prop.as_ptr(), 0, &mut v)?;
        if v.is_null() {
            return Ok(String::new());
        }
        // SAFETY: the host returned a NUL-terminated string it keeps alive for this call.
        let s = unsafe { CStr::from_ptr(v) };
        Ok(s.to_string_lossy().into_owned())
    }

    /// Int `prop`.
    pub fn int(&self, prop: &CStr) -> Result<i32> {
        let mut v: c_int = 0;
        call!(self, propGetInt, prop, prop.as_ptr(), 0, &mut v)?;
        Ok(v)
    }

    /// The first `N` dimensions of int `prop`.
    pub fn ints<const N: usize>(&self, prop: &CStr) -> Result<[i32; N]> {
        let mut v = [0 as c_int; N];
        call!(
            self,
            propGetIntN,
            prop,
            prop.as_ptr(),
            N as c_int,
            v.as_mut_ptr()
        )?;
        Ok(v)
    }

    /// Double `prop`.
    pub fn double(&self, prop: &CStr) -> Result<f64> {
        let mut v = 0.0;
        call!(self, propGetDouble, prop, prop.as_ptr(), 0, &mut v)?;
        Ok(v)
    }

    /// The first `N` dimensions of double `prop`.
    pub fn doubles<const N: usize>(&self, prop: &CStr) -> Result<[f64; N]> {
        let mut v = [0.0; N];
        call!(
            self,
            propGetDoubleN,
            prop,
            prop.as_ptr(),
            N as c_int,
            v.as_mut_ptr()
        )?;
        Ok(v)
    }

    /// Pointer `prop`.
    pub fn pointer(&self, prop: &CStr) -> Result<*mut c_void> {
        let mut v: *mut c_void = std::ptr::null_mut();
        call!(self, propGetPointer, prop, prop.as_ptr(), 0, &mut v)?;
        Ok(v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_the_bindings_strings() {
        assert_eq!(name(openfx_sys::kOfxPropLabel).to_bytes(), b"OfxPropLabel");
        assert_eq!(name(b"no nul").to_bytes(), b"(bad property name)");
        assert_eq!(c_string("a\0b").as_bytes(), b"a b");
    }
}
