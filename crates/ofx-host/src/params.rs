//! Parameters: descriptors defined by the plugin, instances holding values, and the
//! parameter suite (`OfxParameterSuiteV1`). Values are constant over time (a host driven by
//! a graph file sets each once), so the keyframe functions report no keys, the derivative
//! is 0 and the integral is the value times the interval.
//!
//! The C-variadic functions (`paramGetValue` and friends) live in `param_shim.c`; they ask
//! [`shape`] how to read their arguments and forward arrays to [`get`] and [`set`].

use std::ffi::{c_char, c_int, c_uint, c_void, CStr, CString};
use std::sync::{Arc, Mutex, OnceLock, PoisonError};

use openfx_sys as ofx;
use openfx_sys::{OfxParamHandle, OfxParamSetHandle, OfxPropertySetHandle, OfxStatus, OfxTime};

use super::handles::{self, Kind};
use super::log::Log;
use super::props::{self, c_string, PropSet, PropValue, Template};
use super::spec::{cstr, ParamType, PropType, SetKind};
use super::status;

/// A parameter's current value.
#[derive(Clone, Debug, PartialEq)]
enum Val {
    None,
    Ints(Vec<i32>),
    Doubles(Vec<f64>),
    String(CString),
}

/// A parameter, descriptor or instance. Boxed and registered while alive.
#[derive(Debug)]
pub(crate) struct Param {
    /// Its name (an instance's is its descriptor's).
    pub(crate) name: Arc<str>,
    /// Its type.
    pub(crate) ty: ParamType,
    /// Its properties.
    pub(crate) props: Box<PropSet>,
    value: Mutex<Val>,
    instance: bool,
    log: Arc<Log>,
    /// A descriptor's: the properties its instances start from, made at the first instance
    /// and shared by all of them until one is written, and the name their sets go by.
    instance_props: OnceLock<Box<Template>>,
}

impl Param {
    fn boxed(
        name: Arc<str>,
        ty: ParamType,
        props: Box<PropSet>,
        instance: bool,
        log: Arc<Log>,
    ) -> Box<Param> {
        let value = Mutex::new(default_value(ty, &props));
        let p = Box::new(Param {
            name,
            ty,
            props,
            value,
            instance,
            log,
            instance_props: OnceLock::new(),
        });
        handles::register(&*p as *const Param, Kind::Param);
        p
    }

    fn handle(&self) -> OfxParamHandle {
        self as *const Param as OfxParamHandle
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Val> {
        self.value.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Sets the value from the host, checked against the declared type and range.
    pub(crate) fn set_value(&self, value: &PropValue) -> Result<(), String> {
        let new = match (self.ty.value_shape(), value) {
            (Some((PropType::Int, n)), PropValue::Int(v)) if v.len() == n => Val::Ints(v.clone()),
            (Some((PropType::Double, n)), PropValue::Double(v)) if v.len() == n => {
                Val::Doubles(v.clone())
            }
            (Some((PropType::String, _)), PropValue::String(v)) if v.len() == 1 => {
                Val::String(c_string(&v[0]))
            }
            _ => {
                return Err(format!(
                    "a {} parameter cannot take {value:?}",
                    self.ty.name()
                ))
            }
        };
        self.check_range(&new)?;
        *self.lock() = new;
        Ok(())
    }

    /// Refuses values outside the declared range (and choices beyond the options).
    fn check_range(&self, v: &Val) -> Result<(), String> {
        let min = self.props.get(cstr(ofx::kOfxParamPropMin));
        let max = self.props.get(cstr(ofx::kOfxParamPropMax));
        let as_f = |p: Option<PropValue>| -> Vec<f64> {
            match p {
                Some(PropValue::Int(v)) => v.into_iter().map(f64::from).collect(),
                Some(PropValue::Double(v)) => v,
                _ => Vec::new(),
            }
        };
        let (min, max) = (as_f(min), as_f(max));
        let values: Vec<f64> = match v {
            Val::Ints(v) => v.iter().map(|&x| f64::from(x)).collect(),
            Val::Doubles(v) => v.clone(),
            _ => Vec::new(),
        };
        for (i, x) in values.iter().enumerate() {
            let lo = min.get(i).copied().unwrap_or(f64::NEG_INFINITY);
            let hi = max.get(i).copied().unwrap_or(f64::INFINITY);
            if !x.is_finite() || *x < lo || *x > hi {
                return Err(format!("{x} is outside the declared range [{lo}, {hi}]"));
            }
        }
        if self.ty == ParamType::Choice {
            let n = self.props.strings(ofx::kOfxParamPropChoiceOption).len();
            if let Val::Ints(v) = v {
                if v[0] < 0 || v[0] as usize >= n {
                    return Err(format!("option {} does not exist ({n} options)", v[0]));
                }
            }
        }
        Ok(())
    }

    /// The value, as the property form.
    pub(crate) fn value(&self) -> PropValue {
        match &*self.lock() {
            Val::None => PropValue::Int(Vec::new()),
            Val::Ints(v) => PropValue::Int(v.clone()),
            Val::Doubles(v) => PropValue::Double(v.clone()),
            Val::String(s) => PropValue::String(vec![s.to_string_lossy().into_owned()]),
        }
    }
}

impl Drop for Param {
    fn drop(&mut self) {
        handles::unregister(self as *const Param);
    }
}

fn default_value(ty: ParamType, props: &PropSet) -> Val {
    match ty.value_shape() {
        None => Val::None,
        Some((_, _)) => match props.get(cstr(ofx::kOfxParamPropDefault)) {
            Some(PropValue::Int(v)) => Val::Ints(v),
            Some(PropValue::Double(v)) => Val::Doubles(v),
            Some(PropValue::String(v)) => {
                Val::String(c_string(v.first().map_or("", String::as_str)))
            }
            _ => Val::None,
        },
    }
}

/// An effect's parameters. Boxed and registered while alive.
#[derive(Debug)]
pub(crate) struct ParamSet {
    /// The set's own properties.
    pub(crate) props: Box<PropSet>,
    #[allow(
        clippy::vec_box,
        reason = "a parameter's address is its handle: it must not move"
    )]
    params: Mutex<Vec<Box<Param>>>,
    edits: Mutex<i32>,
    instance: bool,
    what: Arc<str>,
    log: Arc<Log>,
    /// A descriptor's: the set properties its instances start from, made at the first
    /// instance and shared by all of them until one is written, and their sets' names.
    instance_props: OnceLock<Box<(Template, Arc<str>)>>,
}

impl ParamSet {
    /// An empty set (a descriptor's, before describeInContext defines parameters).
    pub(crate) fn new(what: &str, instance: bool, log: Arc<Log>) -> Box<ParamSet> {
        let props = props::new_set(
            SetKind::ParamSet,
            "",
            format!("{what} parameter set"),
            Some(log.clone()),
        );
        ParamSet::boxed(props, what.into(), instance, log)
    }

    fn boxed(props: Box<PropSet>, what: Arc<str>, instance: bool, log: Arc<Log>) -> Box<ParamSet> {
        let set = Box::new(ParamSet {
            props,
            params: Mutex::new(Vec::new()),
            edits: Mutex::new(0),
            instance,
            what,
            log,
            instance_props: OnceLock::new(),
        });
        handles::register(&*set as *const ParamSet, Kind::ParamSet);
        set
    }

    /// An instance's set (`what`: the instance, the same for every instance of this
    /// descriptor): every descriptor parameter, at its default.
    pub(crate) fn instantiate(&self, what: &str, log: Arc<Log>) -> Box<ParamSet> {
        let (template, instance_what) = &**self.instance_props.get_or_init(|| {
            let props = props::new_set(
                SetKind::ParamSet,
                "",
                format!("{what} parameter set"),
                Some(log.clone()),
            );
            let what_set = format!("{what} parameter set").into();
            Box::new((
                Template {
                    props,
                    what: what_set,
                },
                what.into(),
            ))
        });
        let props = template.instance(Some(log.clone()));
        let set = ParamSet::boxed(props, Arc::clone(instance_what), true, log.clone());
        let mut params = Vec::new();
        for d in self
            .params
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .iter()
        {
            let template = d.instance_props.get_or_init(|| {
                let props = props::new_set(
                    SetKind::ParamInst(d.ty),
                    &d.name,
                    format!("{} parameter {} (instances' defaults)", self.what, d.name),
                    Some(log.clone()),
                );
                props.copy_values_from(&d.props);
                props.set_str(ofx::kOfxPropType, cstr(ofx::kOfxTypeParameterInstance));
                Box::new(Template {
                    props,
                    what: format!("{what} parameter {}", d.name).into(),
                })
            });
            let props = template.instance(Some(log.clone()));
            params.push(Param::boxed(
                Arc::clone(&d.name),
                d.ty,
                props,
                true,
                log.clone(),
            ));
        }
        *set.params.lock().unwrap_or_else(PoisonError::into_inner) = params;
        set
    }

    /// The handle the plugin gets.
    pub(crate) fn handle(&self) -> OfxParamSetHandle {
        self as *const ParamSet as OfxParamSetHandle
    }

    /// Runs `f` on every parameter, in definition order.
    pub(crate) fn each<R>(&self, mut f: impl FnMut(&Param) -> R) -> Vec<R> {
        self.params
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .iter()
            .map(|p| f(p))
            .collect()
    }

    /// Runs `f` on the parameter `name`.
    pub(crate) fn with<R>(&self, name: &str, f: impl FnOnce(&Param) -> R) -> Option<R> {
        self.params
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .iter()
            .find(|p| &*p.name == name)
            .map(|p| f(p))
    }

    fn find(&self, name: &str) -> Option<*const Param> {
        self.with(name, |p| p as *const Param)
    }
}

impl Drop for ParamSet {
    fn drop(&mut self) {
        handles::unregister(self as *const ParamSet);
    }
}

// The C-variadic functions of the suite, defined in `param_shim.c`.
extern "C" {
    fn nerfx_param_get_value(param: OfxParamHandle, ...) -> OfxStatus;
    fn nerfx_param_get_value_at_time(param: OfxParamHandle, time: OfxTime, ...) -> OfxStatus;
    fn nerfx_param_get_derivative(param: OfxParamHandle, time: OfxTime, ...) -> OfxStatus;
    fn nerfx_param_get_integral(
        param: OfxParamHandle,
        time1: OfxTime,
        time2: OfxTime,
        ...
    ) -> OfxStatus;
    fn nerfx_param_set_value(param: OfxParamHandle, ...) -> OfxStatus;
    fn nerfx_param_set_value_at_time(param: OfxParamHandle, time: OfxTime, ...) -> OfxStatus;
}

/// The suite the plugin fetches.
pub(crate) fn suite() -> ofx::OfxParameterSuiteV1 {
    ofx::OfxParameterSuiteV1 {
        paramDefine: Some(define),
        paramGetHandle: Some(get_handle),
        paramSetGetPropertySet: Some(set_get_property_set),
        paramGetPropertySet: Some(get_property_set),
        paramGetValue: Some(nerfx_param_get_value),
        paramGetValueAtTime: Some(nerfx_param_get_value_at_time),
        paramGetDerivative: Some(nerfx_param_get_derivative),
        paramGetIntegral: Some(nerfx_param_get_integral),
        paramSetValue: Some(nerfx_param_set_value),
        paramSetValueAtTime: Some(nerfx_param_set_value_at_time),
        paramGetNumKeys: Some(get_num_keys),
        paramGetKeyTime: Some(get_key_time),
        paramGetKeyIndex: Some(get_key_index),
        paramDeleteKey: Some(delete_key),
        paramDeleteAllKeys: Some(delete_all_keys),
        paramCopy: Some(copy),
        paramEditBegin: Some(edit_begin),
        paramEditEnd: Some(edit_end),
    }
}

/// # Safety
/// `h` is any pointer; it is checked against the live handles.
unsafe fn param_set<'a>(h: OfxParamSetHandle, function: &str) -> Result<&'a ParamSet, OfxStatus> {
    // SAFETY: checked against the registry.
    unsafe { handles::resolve(h as *const ParamSet, Kind::ParamSet, function) }
        .ok_or(status::ERR_BAD_HANDLE)
}

/// # Safety
/// `h` is any pointer; it is checked against the live handles.
pub(crate) unsafe fn param<'a>(h: *const c_void, function: &str) -> Result<&'a Param, OfxStatus> {
    // SAFETY: checked against the registry.
    unsafe { handles::resolve(h as *const Param, Kind::Param, function) }
        .ok_or(status::ERR_BAD_HANDLE)
}

/// # Safety
/// `s` must be NULL or a C string.
unsafe fn name_of<'a>(s: *const c_char, log: &Log, function: &str) -> Result<&'a str, OfxStatus> {
    if s.is_null() {
        log.violation(format!("{function}: NULL name"));
        return Err(status::ERR_UNKNOWN);
    }
    // SAFETY: checked non-NULL; a C string by contract.
    unsafe { CStr::from_ptr(s) }.to_str().map_err(|_| {
        log.violation(format!("{function}: name is not UTF-8"));
        status::ERR_UNKNOWN
    })
}

/// Writes `value` through `out` when `out` is not NULL.
///
/// # Safety
/// `out` must be NULL or writable.
pub(crate) unsafe fn put<T>(out: *mut T, value: T) {
    if !out.is_null() {
        // SAFETY: checked non-NULL; writable by contract.
        unsafe { out.write(value) };
    }
}

fn result(r: Result<(), OfxStatus>) -> OfxStatus {
    r.err().unwrap_or(status::OK)
}

unsafe extern "C" fn define(
    h: OfxParamSetHandle,
    ty: *const c_char,
    name: *const c_char,
    props_out: *mut OfxPropertySetHandle,
) -> OfxStatus {
    let f = "paramDefine";
    // SAFETY: handles and strings are checked as the suite's contract allows.
    result((|| unsafe {
        let set = param_set(h, f)?;
        let ty_name = name_of(ty, &set.log, f)?;
        let name = name_of(name, &set.log, f)?;
        if set.instance {
            set.log.violation(format!(
                "{f}(\"{name}\"): called on an instance's parameter set"
            ));
            return Err(status::ERR_BAD_HANDLE);
        }
        let Some(t) = ParamType::from_name(ty_name) else {
            set.log.violation(format!(
                "{f}(\"{name}\"): parameter type {ty_name} is not supported by this host"
            ));
            return Err(status::ERR_UNSUPPORTED);
        };
        if set.find(name).is_some() {
            set.log.violation(format!("{f}(\"{name}\"): defined twice"));
            return Err(status::ERR_EXISTS);
        }
        let props = props::new_set(
            SetKind::ParamDesc(t),
            name,
            format!("{} parameter {name}", set.what),
            Some(set.log.clone()),
        );
        props.set_str(ofx::kOfxPropType, cstr(ofx::kOfxTypeParameter));
        props.set_str(ofx::kOfxParamPropType, t.name());
        put(props_out, props.handle());
        let p = Param::boxed(name.into(), t, props, false, set.log.clone());
        set.params
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push(p);
        Ok(())
    })())
}

unsafe extern "C" fn get_handle(
    h: OfxParamSetHandle,
    name: *const c_char,
    out: *mut OfxParamHandle,
    props_out: *mut OfxPropertySetHandle,
) -> OfxStatus {
    let f = "paramGetHandle";
    // SAFETY: handles and strings are checked as the suite's contract allows.
    result((|| unsafe {
        let set = param_set(h, f)?;
        let name = name_of(name, &set.log, f)?;
        let Some(p) = set.find(name) else {
            set.log.violation(format!(
                "{f}(\"{name}\"): no such parameter in {}",
                set.what
            ));
            return Err(status::ERR_UNKNOWN);
        };
        let p = &*p;
        put(out, p.handle());
        put(props_out, p.props.handle());
        Ok(())
    })())
}

unsafe extern "C" fn set_get_property_set(
    h: OfxParamSetHandle,
    out: *mut OfxPropertySetHandle,
) -> OfxStatus {
    // SAFETY: the handle is checked; `out` is writable by contract.
    result((|| unsafe {
        let set = param_set(h, "paramSetGetPropertySet")?;
        put(out, set.props.handle());
        Ok(())
    })())
}

unsafe extern "C" fn get_property_set(
    h: OfxParamHandle,
    out: *mut OfxPropertySetHandle,
) -> OfxStatus {
    // SAFETY: the handle is checked; `out` is writable by contract.
    result((|| unsafe {
        let p = param(h as *const c_void, "paramGetPropertySet")?;
        put(out, p.props.handle());
        Ok(())
    })())
}

/// How the shim reads a parameter's value: its kind (see `nerfx_shim.h`) and dimension.
pub(crate) fn shape(p: &Param) -> (c_int, c_int) {
    match p.ty.value_shape() {
        None => (0, 0),
        Some((PropType::Int, n)) => (1, n as c_int),
        Some((PropType::Double, n)) => (2, n as c_int),
        Some((_, n)) => (3, n as c_int),
    }
}

/// The value (query 0), derivative (1) or integral over `[t1, t2]` (2) of a parameter.
pub(crate) fn get(
    p: &Param,
    query: c_int,
    t1: f64,
    t2: f64,
    doubles: &mut [f64],
    ints: &mut [c_int],
    string: &mut *const c_char,
) -> OfxStatus {
    let f = ["paramGetValue", "paramGetDerivative", "paramGetIntegral"];
    let function = f.get(query as usize).copied().unwrap_or("paramGetValue");
    if !p.instance {
        p.log.violation(format!(
            "{function}(\"{}\"): a descriptor has no value",
            p.name
        ));
        return status::ERR_BAD_HANDLE;
    }
    let value = p.lock();
    match (&*value, query) {
        (Val::Ints(v), 0) => ints[..v.len()].copy_from_slice(v),
        (Val::Doubles(v), 0) => doubles[..v.len()].copy_from_slice(v),
        (Val::Doubles(v), 1) => doubles[..v.len()].fill(0.0),
        (Val::Doubles(v), _) => {
            for (d, x) in doubles.iter_mut().zip(v) {
                *d = x * (t2 - t1);
            }
        }
        (Val::String(s), 0) => *string = s.as_ptr(),
        _ => {
            p.log.violation(format!(
                "{function}(\"{}\"): not defined for a {} parameter",
                p.name,
                p.ty.name()
            ));
            return status::ERR_VALUE;
        }
    }
    status::OK
}

/// Sets a parameter's value from the plugin.
///
/// # Safety
/// `string` must be NULL or a C string.
pub(crate) unsafe fn set(
    p: &Param,
    doubles: &[f64],
    ints: &[c_int],
    string: *const c_char,
) -> OfxStatus {
    if !p.instance {
        p.log.violation(format!(
            "paramSetValue(\"{}\"): a descriptor has no value",
            p.name
        ));
        return status::ERR_BAD_HANDLE;
    }
    let value = match p.ty.value_shape() {
        Some((PropType::Int, n)) => PropValue::Int(ints[..n].to_vec()),
        Some((PropType::Double, n)) => PropValue::Double(doubles[..n].to_vec()),
        Some(_) if !string.is_null() => {
            // SAFETY: checked non-NULL; a C string by contract.
            let s = unsafe { CStr::from_ptr(string) };
            PropValue::String(vec![s.to_string_lossy().into_owned()])
        }
        _ => {
            p.log
                .violation(format!("paramSetValue(\"{}\"): no value to set", p.name));
            return status::ERR_VALUE;
        }
    };
    match p.set_value(&value) {
        Ok(()) => status::OK,
        Err(why) => {
            p.log
                .violation(format!("paramSetValue(\"{}\"): {why}", p.name));
            status::ERR_VALUE
        }
    }
}

unsafe extern "C" fn get_num_keys(h: OfxParamHandle, n: *mut c_uint) -> OfxStatus {
    // SAFETY: the handle is checked; `n` is writable by contract.
    result((|| unsafe {
        param(h as *const c_void, "paramGetNumKeys")?;
        put(n, 0);
        Ok(())
    })())
}

unsafe extern "C" fn get_key_time(
    h: OfxParamHandle,
    _nth: c_uint,
    _time: *mut OfxTime,
) -> OfxStatus {
    // SAFETY: the handle is checked.
    result(unsafe { param(h as *const c_void, "paramGetKeyTime") }.and(Err(status::ERR_BAD_INDEX)))
}

unsafe extern "C" fn get_key_index(
    h: OfxParamHandle,
    _time: OfxTime,
    _direction: c_int,
    _index: *mut c_int,
) -> OfxStatus {
    // SAFETY: the handle is checked.
    result(unsafe { param(h as *const c_void, "paramGetKeyIndex") }.and(Err(status::FAILED)))
}

unsafe extern "C" fn delete_key(h: OfxParamHandle, _time: OfxTime) -> OfxStatus {
    // SAFETY: the handle is checked.
    result(unsafe { param(h as *const c_void, "paramDeleteKey") }.and(Err(status::ERR_BAD_INDEX)))
}

unsafe extern "C" fn delete_all_keys(h: OfxParamHandle) -> OfxStatus {
    // SAFETY: the handle is checked.
    result(unsafe { param(h as *const c_void, "paramDeleteAllKeys") }.map(|_| ()))
}

unsafe extern "C" fn copy(
    to: OfxParamHandle,
    from: OfxParamHandle,
    _offset: OfxTime,
    _range: *const ofx::OfxRangeD,
) -> OfxStatus {
    // SAFETY: both handles are checked.
    result((|| unsafe {
        let to = param(to as *const c_void, "paramCopy")?;
        let from = param(from as *const c_void, "paramCopy")?;
        if to.ty != from.ty || !to.instance || !from.instance {
            to.log.violation(format!(
                "paramCopy(\"{}\", \"{}\"): different types or not instances",
                to.name, from.name
            ));
            return Err(status::ERR_VALUE);
        }
        let v = from.lock().clone();
        *to.lock() = v;
        Ok(())
    })())
}

unsafe extern "C" fn edit_begin(h: OfxParamSetHandle, _name: *const c_char) -> OfxStatus {
    // SAFETY: the handle is checked.
    result((|| unsafe {
        let set = param_set(h, "paramEditBegin")?;
        *set.edits.lock().unwrap_or_else(PoisonError::into_inner) += 1;
        Ok(())
    })())
}

unsafe extern "C" fn edit_end(h: OfxParamSetHandle) -> OfxStatus {
    // SAFETY: the handle is checked.
    result((|| unsafe {
        let set = param_set(h, "paramEditEnd")?;
        let mut edits = set.edits.lock().unwrap_or_else(PoisonError::into_inner);
        if *edits == 0 {
            set.log.violation("paramEditEnd without paramEditBegin");
            return Err(status::FAILED);
        }
        *edits -= 1;
        Ok(())
    })())
}
