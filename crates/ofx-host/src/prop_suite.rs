//! The property suite (`OfxPropertySuiteV1`): every function resolves its handle, reads the
//! name, and hands over to the checked [`PropSet`] accessors.

use std::ffi::{c_char, c_int, c_void, CStr};

use openfx_sys::{OfxPropertySetHandle, OfxPropertySuiteV1, OfxStatus};

use super::handles::{self, Kind};
use super::props::{One, PropSet};
use super::spec::PropType;
use super::status;

/// The suite the plugin fetches.
pub(crate) static SUITE: OfxPropertySuiteV1 = OfxPropertySuiteV1 {
    propSetPointer: Some(set_pointer),
    propSetString: Some(set_string),
    propSetDouble: Some(set_double),
    propSetInt: Some(set_int),
    propSetPointerN: Some(set_pointer_n),
    propSetStringN: Some(set_string_n),
    propSetDoubleN: Some(set_double_n),
    propSetIntN: Some(set_int_n),
    propGetPointer: Some(get_pointer),
    propGetString: Some(get_string),
    propGetDouble: Some(get_double),
    propGetInt: Some(get_int),
    propGetPointerN: Some(get_pointer_n),
    propGetStringN: Some(get_string_n),
    propGetDoubleN: Some(get_double_n),
    propGetIntN: Some(get_int_n),
    propReset: Some(reset),
    propGetDimension: Some(get_dimension),
};

/// The set and the property name, or the status to return.
///
/// # Safety
/// `name` must be NULL or a C string.
unsafe fn target<'a>(
    handle: OfxPropertySetHandle,
    name: *const c_char,
    function: &str,
) -> Result<(&'a PropSet, &'a str), OfxStatus> {
    // SAFETY: live handles point to boxed sets.
    let set = unsafe { handles::resolve(handle as *const PropSet, Kind::PropSet, function) }
        .ok_or(status::ERR_BAD_HANDLE)?;
    if name.is_null() {
        set.log()
            .violation(format!("{function}: NULL property name"));
        return Err(status::ERR_UNKNOWN);
    }
    // SAFETY: checked non-NULL; the plugin passes a C string.
    match unsafe { CStr::from_ptr(name) }.to_str() {
        Ok(n) => Ok((set, n)),
        Err(_) => {
            set.log()
                .violation(format!("{function}: property name is not UTF-8"));
            Err(status::ERR_UNKNOWN)
        }
    }
}

fn done(r: Result<(), OfxStatus>) -> OfxStatus {
    r.err().unwrap_or(status::OK)
}

/// # Safety
/// As for the suite's set functions.
unsafe fn set_one(
    h: OfxPropertySetHandle,
    name: *const c_char,
    index: c_int,
    value: One,
    function: &str,
) -> OfxStatus {
    // SAFETY: forwarded from the suite function's contract.
    done(
        unsafe { target(h, name, function) }
            .and_then(|(set, n)| unsafe { set.plugin_set(function, n, index, value) }),
    )
}

/// # Safety
/// `values` must hold `count` values when `count` > 0.
unsafe fn set_many<T: Copy>(
    h: OfxPropertySetHandle,
    name: *const c_char,
    count: c_int,
    values: *const T,
    ty: PropType,
    wrap: impl Fn(T) -> One,
    function: &str,
) -> OfxStatus {
    // SAFETY: forwarded from the suite function's contract.
    let (set, n) = match unsafe { target(h, name, function) } {
        Ok(t) => t,
        Err(s) => return s,
    };
    let Ok(count) = usize::try_from(count) else {
        set.log()
            .violation(format!("{function}(\"{n}\"): negative count {count}"));
        return status::ERR_BAD_INDEX;
    };
    if count > 0 && values.is_null() {
        set.log()
            .violation(format!("{function}(\"{n}\"): NULL values"));
        return status::ERR_VALUE;
    }
    // SAFETY: the plugin passes `count` values.
    let slice = if count == 0 {
        &[][..]
    } else {
        unsafe { std::slice::from_raw_parts(values, count) }
    };
    let ones: Vec<One> = slice.iter().map(|&v| wrap(v)).collect();
    // SAFETY: string values come from the plugin as C strings.
    done(unsafe { set.plugin_set_n(function, n, ty, &ones) })
}

/// # Safety
/// `out` must be writable.
unsafe fn get_one<T>(
    h: OfxPropertySetHandle,
    name: *const c_char,
    index: c_int,
    out: *mut T,
    ty: PropType,
    unwrap: impl Fn(One) -> Option<T>,
    function: &str,
) -> OfxStatus {
    // SAFETY: forwarded from the suite function's contract.
    let (set, n) = match unsafe { target(h, name, function) } {
        Ok(t) => t,
        Err(s) => return s,
    };
    if out.is_null() {
        set.log()
            .violation(format!("{function}(\"{n}\"): NULL destination"));
        return status::ERR_VALUE;
    }
    match set.plugin_get(function, n, ty, index).map(&unwrap) {
        Ok(Some(v)) => {
            // SAFETY: checked non-NULL; the plugin passes a writable location.
            unsafe { out.write(v) };
            status::OK
        }
        Ok(None) => status::ERR_VALUE,
        Err(s) => s,
    }
}

/// # Safety
/// `out` must have room for `count` values.
unsafe fn get_many<T>(
    h: OfxPropertySetHandle,
    name: *const c_char,
    count: c_int,
    out: *mut T,
    ty: PropType,
    unwrap: impl Fn(One) -> Option<T>,
    function: &str,
) -> OfxStatus {
    // SAFETY: forwarded from the suite function's contract.
    let (set, n) = match unsafe { target(h, name, function) } {
        Ok(t) => t,
        Err(s) => return s,
    };
    if count > 0 && out.is_null() {
        set.log()
            .violation(format!("{function}(\"{n}\"): NULL destination"));
        return status::ERR_VALUE;
    }
    match set.plugin_get_n(function, n, ty, count) {
        Ok(values) => {
            for (i, v) in values.into_iter().enumerate() {
                match unwrap(v) {
                    // SAFETY: the plugin passes room for `count` values; i < count.
                    Some(v) => unsafe { out.add(i).write(v) },
                    None => return status::ERR_VALUE,
                }
            }
            status::OK
        }
        Err(s) => s,
    }
}

fn as_int(v: One) -> Option<c_int> {
    match v {
        One::Int(x) => Some(x),
        _ => None,
    }
}
fn as_double(v: One) -> Option<f64> {
    match v {
        One::Double(x) => Some(x),
        _ => None,
    }
}
fn as_string(v: One) -> Option<*mut c_char> {
    match v {
        One::String(x) => Some(x as *mut c_char),
        _ => None,
    }
}
fn as_pointer(v: One) -> Option<*mut c_void> {
    match v {
        One::Pointer(x) => Some(x as *mut c_void),
        _ => None,
    }
}

unsafe extern "C" fn set_pointer(
    h: OfxPropertySetHandle,
    name: *const c_char,
    index: c_int,
    value: *mut c_void,
) -> OfxStatus {
    // SAFETY: the suite's contract.
    unsafe {
        set_one(
            h,
            name,
            index,
            One::Pointer(value as usize),
            "propSetPointer",
        )
    }
}
unsafe extern "C" fn set_string(
    h: OfxPropertySetHandle,
    name: *const c_char,
    index: c_int,
    value: *const c_char,
) -> OfxStatus {
    // SAFETY: the suite's contract.
    unsafe { set_one(h, name, index, One::String(value), "propSetString") }
}
unsafe extern "C" fn set_double(
    h: OfxPropertySetHandle,
    name: *const c_char,
    index: c_int,
    value: f64,
) -> OfxStatus {
    // SAFETY: the suite's contract.
    unsafe { set_one(h, name, index, One::Double(value), "propSetDouble") }
}
unsafe extern "C" fn set_int(
    h: OfxPropertySetHandle,
    name: *const c_char,
    index: c_int,
    value: c_int,
) -> OfxStatus {
    // SAFETY: the suite's contract.
    unsafe { set_one(h, name, index, One::Int(value), "propSetInt") }
}
unsafe extern "C" fn set_pointer_n(
    h: OfxPropertySetHandle,
    name: *const c_char,
    count: c_int,
    values: *const *mut c_void,
) -> OfxStatus {
    // SAFETY: the suite's contract.
    unsafe {
        set_many(
            h,
            name,
            count,
            values,
            PropType::Pointer,
            |v| One::Pointer(v as usize),
            "propSetPointerN",
        )
    }
}
unsafe extern "C" fn set_string_n(
    h: OfxPropertySetHandle,
    name: *const c_char,
    count: c_int,
    values: *const *const c_char,
) -> OfxStatus {
    // SAFETY: the suite's contract.
    unsafe {
        set_many(
            h,
            name,
            count,
            values,
            PropType::String,
            One::String,
            "propSetStringN",
        )
    }
}
unsafe extern "C" fn set_double_n(
    h: OfxPropertySetHandle,
    name: *const c_char,
    count: c_int,
    values: *const f64,
) -> OfxStatus {
    // SAFETY: the suite's contract.
    unsafe {
        set_many(
            h,
            name,
            count,
            values,
            PropType::Double,
            One::Double,
            "propSetDoubleN",
        )
    }
}
unsafe extern "C" fn set_int_n(
    h: OfxPropertySetHandle,
    name: *const c_char,
    count: c_int,
    values: *const c_int,
) -> OfxStatus {
    // SAFETY: the suite's contract.
    unsafe {
        set_many(
            h,
            name,
            count,
            values,
            PropType::Int,
            One::Int,
            "propSetIntN",
        )
    }
}
unsafe extern "C" fn get_pointer(
    h: OfxPropertySetHandle,
    name: *const c_char,
    index: c_int,
    out: *mut *mut c_void,
) -> OfxStatus {
    // SAFETY: the suite's contract.
    unsafe {
        get_one(
            h,
            name,
            index,
            out,
            PropType::Pointer,
            as_pointer,
            "propGetPointer",
        )
    }
}
unsafe extern "C" fn get_string(
    h: OfxPropertySetHandle,
    name: *const c_char,
    index: c_int,
    out: *mut *mut c_char,
) -> OfxStatus {
    // SAFETY: the suite's contract.
    unsafe {
        get_one(
            h,
            name,
            index,
            out,
            PropType::String,
            as_string,
            "propGetString",
        )
    }
}
unsafe extern "C" fn get_double(
    h: OfxPropertySetHandle,
    name: *const c_char,
    index: c_int,
    out: *mut f64,
) -> OfxStatus {
    // SAFETY: the suite's contract.
    unsafe {
        get_one(
            h,
            name,
            index,
            out,
            PropType::Double,
            as_double,
            "propGetDouble",
        )
    }
}
unsafe extern "C" fn get_int(
    h: OfxPropertySetHandle,
    name: *const c_char,
    index: c_int,
    out: *mut c_int,
) -> OfxStatus {
    // SAFETY: the suite's contract.
    unsafe { get_one(h, name, index, out, PropType::Int, as_int, "propGetInt") }
}
unsafe extern "C" fn get_pointer_n(
    h: OfxPropertySetHandle,
    name: *const c_char,
    count: c_int,
    out: *mut *mut c_void,
) -> OfxStatus {
    // SAFETY: the suite's contract.
    unsafe {
        get_many(
            h,
            name,
            count,
            out,
            PropType::Pointer,
            as_pointer,
            "propGetPointerN",
        )
    }
}
unsafe extern "C" fn get_string_n(
    h: OfxPropertySetHandle,
    name: *const c_char,
    count: c_int,
    out: *mut *mut c_char,
) -> OfxStatus {
    // SAFETY: the suite's contract.
    unsafe {
        get_many(
            h,
            name,
            count,
            out,
            PropType::String,
            as_string,
            "propGetStringN",
        )
    }
}
unsafe extern "C" fn get_double_n(
    h: OfxPropertySetHandle,
    name: *const c_char,
    count: c_int,
    out: *mut f64,
) -> OfxStatus {
    // SAFETY: the suite's contract.
    unsafe {
        get_many(
            h,
            name,
            count,
            out,
            PropType::Double,
            as_double,
            "propGetDoubleN",
        )
    }
}
unsafe extern "C" fn get_int_n(
    h: OfxPropertySetHandle,
    name: *const c_char,
    count: c_int,
    out: *mut c_int,
) -> OfxStatus {
    // SAFETY: the suite's contract.
    unsafe { get_many(h, name, count, out, PropType::Int, as_int, "propGetIntN") }
}
unsafe extern "C" fn reset(h: OfxPropertySetHandle, name: *const c_char) -> OfxStatus {
    // SAFETY: the suite's contract.
    done(
        unsafe { target(h, name, "propReset") }
            .and_then(|(set, n)| set.plugin_reset("propReset", n)),
    )
}
unsafe extern "C" fn get_dimension(
    h: OfxPropertySetHandle,
    name: *const c_char,
    count: *mut c_int,
) -> OfxStatus {
    // SAFETY: the suite's contract.
    let (set, n) = match unsafe { target(h, name, "propGetDimension") } {
        Ok(t) => t,
        Err(s) => return s,
    };
    if count.is_null() {
        set.log()
            .violation(format!("propGetDimension(\"{n}\"): NULL destination"));
        return status::ERR_VALUE;
    }
    match set.plugin_dimension("propGetDimension", n) {
        Ok(d) => {
            // SAFETY: checked non-NULL.
            unsafe { count.write(d as c_int) };
            status::OK
        }
        Err(s) => s,
    }
}
