//! Typed property sets, checked against the spec's table ([`super::spec`]) on every access.
//!
//! A set holds, for each property it may carry, a value of the property's type and dimension
//! and whether the plugin may write it. The plugin's accesses ([`PropSet::plugin_get`] and
//! friends, used by the property suite) return the spec's status for an unknown name
//! (`kOfxStatErrUnknown`), a wrong type or a read-only property (`kOfxStatErrValue`) and an
//! index out of range (`kOfxStatErrBadIndex`), and record each as a violation. The host's own
//! accesses go through typed methods that report its mistakes as errors.

use std::collections::BTreeMap;
use std::ffi::{c_char, CStr, CString};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

use super::handles::{self, Kind};
use super::log::Log;
use super::spec::{self, Def, Dim, PropType, SetKind};
use super::status::{self, Status};

/// Property values, one vector per property.
#[derive(Clone, Debug, PartialEq)]
pub enum PropValue {
    /// Ints.
    Int(Vec<i32>),
    /// Doubles.
    Double(Vec<f64>),
    /// Strings.
    String(Vec<String>),
    /// Pointers (as addresses).
    Pointer(Vec<usize>),
}

/// The stored form: strings as C strings, so the pointers handed out stay valid until the
/// property changes.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Stored {
    Int(Vec<i32>),
    Double(Vec<f64>),
    String(Vec<CString>),
    Pointer(Vec<usize>),
}

impl Stored {
    fn len(&self) -> usize {
        match self {
            Stored::Int(v) => v.len(),
            Stored::Double(v) => v.len(),
            Stored::String(v) => v.len(),
            Stored::Pointer(v) => v.len(),
        }
    }

    fn ty(&self) -> PropType {
        match self {
            Stored::Int(_) => PropType::Int,
            Stored::Double(_) => PropType::Double,
            Stored::String(_) => PropType::String,
            Stored::Pointer(_) => PropType::Pointer,
        }
    }

    /// The public form.
    pub(crate) fn to_value(&self) -> PropValue {
        match self {
            Stored::Int(v) => PropValue::Int(v.clone()),
            Stored::Double(v) => PropValue::Double(v.clone()),
            Stored::String(v) => {
                PropValue::String(v.iter().map(|s| s.to_string_lossy().into_owned()).collect())
            }
            Stored::Pointer(v) => PropValue::Pointer(v.clone()),
        }
    }

    fn from_value(value: &PropValue) -> Stored {
        match value {
            PropValue::Int(v) => Stored::Int(v.clone()),
            PropValue::Double(v) => Stored::Double(v.clone()),
            PropValue::String(v) => Stored::String(v.iter().map(|s| c_string(s)).collect()),
            PropValue::Pointer(v) => Stored::Pointer(v.clone()),
        }
    }
}

/// `s` as a C string, cut at an interior NUL.
pub(crate) fn c_string(s: &str) -> CString {
    let end = s.find('\0').unwrap_or(s.len());
    CString::new(&s[..end]).unwrap_or_default()
}

/// One value of a property, as the suite passes it.
#[derive(Clone, Copy, Debug)]
pub(crate) enum One {
    Int(i32),
    Double(f64),
    String(*const c_char),
    Pointer(usize),
}

impl One {
    fn ty(&self) -> PropType {
        match self {
            One::Int(_) => PropType::Int,
            One::Double(_) => PropType::Double,
            One::String(_) => PropType::String,
            One::Pointer(_) => PropType::Pointer,
        }
    }
}

#[derive(Clone, Debug)]
struct Entry {
    value: Stored,
    default: Stored,
    dim: Dim,
    writable: bool,
}

/// A set's entries: those it shares with the sets made from the same template, and the
/// ones it has changed since, each in place of the shared entry of its name.
#[derive(Debug)]
struct Entries {
    /// Written in place while no other set holds them.
    shared: Arc<BTreeMap<Arc<str>, Entry>>,
    /// This set's changed entries (few: an instance writes one or two of its properties).
    own: Vec<(Arc<str>, Entry)>,
}

impl Entries {
    fn new(entries: BTreeMap<Arc<str>, Entry>) -> Entries {
        Entries {
            shared: Arc::new(entries),
            own: Vec::new(),
        }
    }

    fn get(&self, name: &str) -> Option<&Entry> {
        match self.own.iter().find(|(n, _)| &**n == name) {
            Some((_, e)) => Some(e),
            None => self.shared.get(name),
        }
    }

    /// The entry `name`, to change: this set's own, the shared one where no other set holds
    /// the shared entries, else a copy of the shared one made this set's own (the shared
    /// entry, and the string pointers handed out from it, stay as they are).
    fn get_mut(&mut self, name: &str) -> Option<&mut Entry> {
        if let Some(at) = self.own.iter().position(|(n, _)| &**n == name) {
            return Some(&mut self.own[at].1);
        }
        if Arc::get_mut(&mut self.shared).is_some() {
            return Arc::get_mut(&mut self.shared).and_then(|m| m.get_mut(name));
        }
        let (key, entry) = self.shared.get_key_value(name)?;
        self.own.reserve_exact(1);
        self.own.push((Arc::clone(key), entry.clone()));
        self.own.last_mut().map(|(_, e)| e)
    }

    /// Every entry, this set's own in place of the shared ones.
    fn each(&self) -> impl Iterator<Item = (&Arc<str>, &Entry)> {
        self.shared.iter().map(|(n, e)| {
            (
                n,
                self.own.iter().find(|(o, _)| o == n).map_or(e, |(_, o)| o),
            )
        })
    }

    /// The names of the entries.
    fn names(&self) -> Vec<Arc<str>> {
        self.shared.keys().cloned().collect()
    }
}

/// What a descriptor's instances start from: the property set theirs share, and the name
/// their sets go by.
#[derive(Debug)]
pub(crate) struct Template {
    /// The set shared ([`PropSet::share`]).
    pub(crate) props: Box<PropSet>,
    /// The instances' sets' name.
    pub(crate) what: Arc<str>,
}

impl Template {
    /// A set for an instance, sharing the template's entries.
    pub(crate) fn instance(&self, log: Option<Arc<Log>>) -> Box<PropSet> {
        self.props.share(Arc::clone(&self.what), log)
    }
}

/// A property set: the host's, an effect's, a clip's, an image's, a parameter's, or an
/// action's arguments. Boxed and registered as a handle while alive.
#[derive(Debug)]
pub(crate) struct PropSet {
    kind: SetKind,
    /// Names the set in violations (`org.nerfx.DepthMerge clip A`); shared by a graph's
    /// instances of one parameter or clip.
    what: Arc<str>,
    /// Shared with the template an instance's set starts from, except those it wrote.
    entries: Mutex<Entries>,
    /// Where violations go; `None`: the log of the action running on the calling thread
    /// (the host's own set, shared by every bundle).
    log: Option<Arc<Log>>,
}

fn default_values(def: Def, ty: PropType, n: usize, name: &str, kind: SetKind) -> Stored {
    let labels = match kind {
        SetKind::ParamDesc(t) | SetKind::ParamInst(t) => spec::dimension_labels(t),
        _ => &[],
    };
    match ty {
        PropType::Int => Stored::Int(vec![
            match def {
                Def::I(v) => v,
                Def::Lowest => i32::MIN,
                Def::Highest => i32::MAX,
                _ => 0,
            };
            n
        ]),
        PropType::Double => Stored::Double(vec![
            match def {
                Def::D(v) => v,
                Def::I(v) => f64::from(v),
                Def::Lowest => -f64::MAX,
                Def::Highest => f64::MAX,
                _ => 0.0,
            };
            n
        ]),
        PropType::String => Stored::String(
            (0..n)
                .map(|i| {
                    c_string(match def {
                        Def::S(s) => s,
                        Def::Name => name,
                        Def::DimLabels => labels.get(i).copied().unwrap_or(""),
                        _ => "",
                    })
                })
                .collect(),
        ),
        PropType::Pointer => Stored::Pointer(vec![0; n]),
    }
}

/// A set of `kind` with every property the spec gives it, at its default; `name` is the
/// object's name (labels default to it).
pub(crate) fn new_set(
    kind: SetKind,
    name: &str,
    what: impl Into<Arc<str>>,
    log: Option<Arc<Log>>,
) -> Box<PropSet> {
    let mut entries = BTreeMap::new();
    for p in spec::all() {
        if let Some(r) = p.on(kind) {
            let n = match r.dim {
                Dim::Fixed(n) => n,
                Dim::Variable => 0,
            };
            let value = default_values(p.default, r.ty, n, name, kind);
            entries.insert(
                Arc::from(p.name),
                Entry {
                    default: value.clone(),
                    value,
                    dim: r.dim,
                    writable: r.writable,
                },
            );
        }
    }
    PropSet::boxed(kind, what, entries, log)
}

/// An action's argument set holding exactly `values` (read-only unless `out`).
pub(crate) fn args(
    out: bool,
    what: String,
    values: &[(&str, PropValue)],
    log: Arc<Log>,
) -> Box<PropSet> {
    let entries = values
        .iter()
        .map(|(name, v)| {
            let value = Stored::from_value(v);
            (
                Arc::from(*name),
                Entry {
                    default: value.clone(),
                    dim: Dim::Fixed(value.len()),
                    value,
                    writable: out,
                },
            )
        })
        .collect();
    PropSet::boxed(SetKind::Args { out }, what, entries, Some(log))
}

impl PropSet {
    fn boxed(
        kind: SetKind,
        what: impl Into<Arc<str>>,
        entries: BTreeMap<Arc<str>, Entry>,
        log: Option<Arc<Log>>,
    ) -> Box<PropSet> {
        let set = Box::new(PropSet {
            kind,
            what: what.into(),
            entries: Mutex::new(Entries::new(entries)),
            log,
        });
        handles::register(&*set as *const PropSet, Kind::PropSet);
        set
    }

    /// The handle the plugin gets.
    pub(crate) fn handle(&self) -> openfx_sys::OfxPropertySetHandle {
        self as *const PropSet as openfx_sys::OfxPropertySetHandle
    }

    /// The log violations go to.
    pub(crate) fn log(&self) -> Arc<Log> {
        self.log.clone().unwrap_or_else(super::log::current)
    }

    fn lock(&self) -> MutexGuard<'_, Entries> {
        self.entries.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// A set of this one's kind holding its entries as they are now, shared with it (so a
    /// graph's instances of one parameter hold one copy of its properties). A write to
    /// either copies just the entry written, leaving the shared one, and the string pointers
    /// handed out from it, as they were. Entries this set changed itself are copied.
    pub(crate) fn share(&self, what: Arc<str>, log: Option<Arc<Log>>) -> Box<PropSet> {
        let entries = {
            let mine = self.lock();
            if mine.own.is_empty() {
                Entries {
                    shared: Arc::clone(&mine.shared),
                    own: Vec::new(),
                }
            } else {
                let all = mine
                    .each()
                    .map(|(n, e)| (Arc::clone(n), e.clone()))
                    .collect();
                Entries::new(all)
            }
        };
        let set = Box::new(PropSet {
            kind: self.kind,
            what,
            entries: Mutex::new(entries),
            log,
        });
        handles::register(&*set as *const PropSet, Kind::PropSet);
        set
    }

    fn violate(&self, function: &str, name: &str, why: String) {
        self.log()
            .violation(format!("{function}({}, \"{name}\"): {why}", self.what));
    }

    /// Why `name` is not on this set, as a violation, or `None` when probing for it is
    /// legitimate (optional host properties).
    fn missing(&self, name: &str) -> Option<String> {
        match spec::lookup(name) {
            None => Some("no such property in the OpenFX spec".to_string()),
            Some(_) if self.kind == SetKind::Host => None,
            Some(_) => Some(format!("not a property of a {:?} property set", self.kind)),
        }
    }

    /// Runs `f` on the entry `name`, or returns the status for a missing one.
    fn with_entry<R>(
        &self,
        function: &str,
        name: &str,
        f: impl FnOnce(&Entry) -> Result<R, (Status, String)>,
    ) -> Result<R, Status> {
        let entries = self.lock();
        let Some(entry) = entries.get(name) else {
            drop(entries);
            return Err(self.unknown(function, name));
        };
        f(entry).map_err(|(s, why)| {
            self.violate(function, name, why);
            s
        })
    }

    /// [`Self::with_entry`] for a change: the entries are copied first where they are shared.
    fn with_entry_mut<R>(
        &self,
        function: &str,
        name: &str,
        f: impl FnOnce(&mut Entry) -> Result<R, (Status, String)>,
    ) -> Result<R, Status> {
        let mut entries = self.lock();
        let Some(entry) = entries.get_mut(name) else {
            drop(entries);
            return Err(self.unknown(function, name));
        };
        f(entry).map_err(|(s, why)| {
            self.violate(function, name, why);
            s
        })
    }

    /// The status for a property `name` the set does not have, reporting it where probing
    /// for it is not legitimate.
    fn unknown(&self, function: &str, name: &str) -> Status {
        if let Some(why) = self.missing(name) {
            self.violate(function, name, why);
        }
        status::ERR_UNKNOWN
    }

    /// The plugin reads component `index` of `name` as `ty`; strings come back as pointers
    /// into the set.
    pub(crate) fn plugin_get(
        &self,
        function: &str,
        name: &str,
        ty: PropType,
        index: i32,
    ) -> Result<One, Status> {
        self.with_entry(function, name, |e| {
            check_type(e, ty)?;
            let i = usize::try_from(index).ok().filter(|&i| i < e.value.len());
            let Some(i) = i else {
                return Err(bad_index(index, e.value.len()));
            };
            Ok(match &e.value {
                Stored::Int(v) => One::Int(v[i]),
                Stored::Double(v) => One::Double(v[i]),
                Stored::String(v) => One::String(v[i].as_ptr()),
                Stored::Pointer(v) => One::Pointer(v[i]),
            })
        })
    }

    /// The plugin reads the first `count` components of `name` as `ty`.
    pub(crate) fn plugin_get_n(
        &self,
        function: &str,
        name: &str,
        ty: PropType,
        count: i32,
    ) -> Result<Vec<One>, Status> {
        self.with_entry(function, name, |e| {
            check_type(e, ty)?;
            let n = usize::try_from(count).ok().filter(|&n| n <= e.value.len());
            let Some(n) = n else {
                return Err(bad_index(count, e.value.len()));
            };
            Ok(match &e.value {
                Stored::Int(v) => v[..n].iter().map(|&x| One::Int(x)).collect(),
                Stored::Double(v) => v[..n].iter().map(|&x| One::Double(x)).collect(),
                Stored::String(v) => v[..n].iter().map(|x| One::String(x.as_ptr())).collect(),
                Stored::Pointer(v) => v[..n].iter().map(|&x| One::Pointer(x)).collect(),
            })
        })
    }

    /// The plugin sets component `index` of `name` (appending when the property has a
    /// variable dimension and `index` is its length).
    ///
    /// # Safety
    /// String values must be NUL-terminated C strings.
    pub(crate) unsafe fn plugin_set(
        &self,
        function: &str,
        name: &str,
        index: i32,
        value: One,
    ) -> Result<(), Status> {
        self.with_entry_mut(function, name, |e| {
            check_writable(e)?;
            check_type(e, value.ty())?;
            let len = e.value.len();
            let limit = match e.dim {
                Dim::Fixed(n) => n.saturating_sub(1),
                Dim::Variable => len,
            };
            let i = usize::try_from(index).ok().filter(|&i| i <= limit);
            let Some(i) = i else {
                return Err(bad_index(index, limit + 1));
            };
            // SAFETY: the caller passes C strings for string properties.
            let value = unsafe { own(value)? };
            put(&mut e.value, i, value);
            Ok(())
        })
    }

    /// The plugin sets the first `values.len()` components (all of them, for a property of
    /// variable dimension).
    ///
    /// # Safety
    /// String values must be NUL-terminated C strings.
    pub(crate) unsafe fn plugin_set_n(
        &self,
        function: &str,
        name: &str,
        ty: PropType,
        values: &[One],
    ) -> Result<(), Status> {
        self.with_entry_mut(function, name, |e| {
            check_writable(e)?;
            check_type(e, ty)?;
            if let Dim::Fixed(n) = e.dim {
                if values.len() > n {
                    return Err(bad_index(values.len() as i32, n));
                }
            } else {
                e.value = empty(ty);
            }
            for (i, v) in values.iter().enumerate() {
                // SAFETY: the caller passes C strings for string properties.
                put(&mut e.value, i, unsafe { own(*v)? });
            }
            Ok(())
        })
    }

    /// The plugin resets `name` to its default.
    pub(crate) fn plugin_reset(&self, function: &str, name: &str) -> Result<(), Status> {
        self.with_entry_mut(function, name, |e| {
            check_writable(e)?;
            e.value = e.default.clone();
            Ok(())
        })
    }

    /// The dimension of `name` as the plugin sees it (the current number of values).
    pub(crate) fn plugin_dimension(&self, function: &str, name: &str) -> Result<usize, Status> {
        self.with_entry(function, name, |e| Ok(e.value.len()))
    }

    /// The host sets `name`; its type must be the property's (a host bug otherwise).
    pub(crate) fn set(&self, name: &str, value: PropValue) -> nerfx_core::Result<()> {
        let mut entries = self.lock();
        let entry = entries.get(name).ok_or_else(|| {
            nerfx_core::Error::invalid(format!("host: {} {name}", self.what), "no such property")
        })?;
        let stored = Stored::from_value(&value);
        let fits = match entry.dim {
            Dim::Fixed(n) => stored.len() == n,
            Dim::Variable => true,
        };
        if stored.ty() != entry.value.ty() || !fits {
            return Err(nerfx_core::Error::invalid(
                format!("host: {} {name}", self.what),
                format!(
                    "{value:?} does not fit {:?} × {:?}",
                    entry.value.ty(),
                    entry.dim
                ),
            ));
        }
        // Setting what is there already leaves shared entries shared.
        if entry.value == stored {
            return Ok(());
        }
        if let Some(entry) = entries.get_mut(name) {
            entry.value = stored;
        }
        Ok(())
    }

    /// [`PropSet::set`], with a failure (a host bug) recorded as a violation so that a
    /// test sees it.
    pub(crate) fn put(&self, name: &str, value: PropValue) {
        if let Err(e) = self.set(name, value) {
            self.log().violation(format!("host bug: {e}"));
        }
    }

    /// The host sets `name` to one string.
    pub(crate) fn set_str(&self, name: &[u8], value: &str) {
        self.put(
            spec::cstr_dyn(name),
            PropValue::String(vec![value.to_string()]),
        )
    }

    /// The host sets `name` to ints.
    pub(crate) fn set_ints(&self, name: &[u8], values: &[i32]) {
        self.put(spec::cstr_dyn(name), PropValue::Int(values.to_vec()))
    }

    /// The host sets `name` to doubles.
    pub(crate) fn set_doubles(&self, name: &[u8], values: &[f64]) {
        self.put(spec::cstr_dyn(name), PropValue::Double(values.to_vec()))
    }

    /// The value of `name`, if the set has it.
    pub(crate) fn get(&self, name: &str) -> Option<PropValue> {
        self.lock().get(name).map(|e| e.value.to_value())
    }

    /// All strings of `name` (empty when absent or not strings).
    pub(crate) fn strings(&self, name: &[u8]) -> Vec<String> {
        match self.get(spec::cstr_dyn(name)) {
            Some(PropValue::String(v)) => v,
            _ => Vec::new(),
        }
    }

    /// The first string of `name`.
    pub(crate) fn string(&self, name: &[u8]) -> String {
        self.strings(name).into_iter().next().unwrap_or_default()
    }

    /// The ints of `name`.
    pub(crate) fn ints(&self, name: &[u8]) -> Vec<i32> {
        match self.get(spec::cstr_dyn(name)) {
            Some(PropValue::Int(v)) => v,
            _ => Vec::new(),
        }
    }

    /// The first int of `name`, or 0.
    pub(crate) fn int(&self, name: &[u8]) -> i32 {
        self.ints(name).first().copied().unwrap_or(0)
    }

    /// The doubles of `name`.
    pub(crate) fn doubles(&self, name: &[u8]) -> Vec<f64> {
        match self.get(spec::cstr_dyn(name)) {
            Some(PropValue::Double(v)) => v,
            _ => Vec::new(),
        }
    }

    /// Every property and its value.
    pub(crate) fn all(&self) -> BTreeMap<String, PropValue> {
        self.lock()
            .each()
            .map(|(k, e)| (k.to_string(), e.value.to_value()))
            .collect()
    }

    /// A copy of every value into a new set of `kind` (a descriptor's values into an
    /// instance), keeping the new set's own writability.
    pub(crate) fn copy_values_from(&self, other: &PropSet) {
        let names = self.lock().names();
        for name in names {
            let Some(value) = other.lock().get(&name).map(|s| s.value.clone()) else {
                continue;
            };
            if let Some(e) = self.lock().get_mut(&name) {
                if value.ty() == e.value.ty() {
                    e.value = value;
                }
            }
        }
    }
}

impl Drop for PropSet {
    fn drop(&mut self) {
        handles::unregister(self as *const PropSet);
    }
}

fn check_type(e: &Entry, ty: PropType) -> Result<(), (Status, String)> {
    if e.value.ty() == ty {
        Ok(())
    } else {
        Err((
            status::ERR_VALUE,
            format!("the property is {:?}, accessed as {ty:?}", e.value.ty()),
        ))
    }
}

fn check_writable(e: &Entry) -> Result<(), (Status, String)> {
    if e.writable {
        Ok(())
    } else {
        Err((status::ERR_VALUE, "read-only for the plugin".to_string()))
    }
}

fn bad_index(index: i32, len: usize) -> (Status, String) {
    (
        status::ERR_BAD_INDEX,
        format!("index {index} out of range (dimension {len})"),
    )
}

fn empty(ty: PropType) -> Stored {
    match ty {
        PropType::Int => Stored::Int(Vec::new()),
        PropType::Double => Stored::Double(Vec::new()),
        PropType::String => Stored::String(Vec::new()),
        PropType::Pointer => Stored::Pointer(Vec::new()),
    }
}

/// A string value copied out of the plugin's memory.
enum Owned {
    Int(i32),
    Double(f64),
    String(CString),
    Pointer(usize),
}

/// # Safety
/// A string value must be NULL or a NUL-terminated C string.
unsafe fn own(value: One) -> Result<Owned, (Status, String)> {
    Ok(match value {
        One::Int(v) => Owned::Int(v),
        One::Double(v) => Owned::Double(v),
        One::Pointer(v) => Owned::Pointer(v),
        One::String(p) if p.is_null() => {
            return Err((status::ERR_VALUE, "NULL string".to_string()))
        }
        // SAFETY: the caller guarantees a C string.
        One::String(p) => Owned::String(unsafe { CStr::from_ptr(p) }.to_owned()),
    })
}

/// Stores `value` at `i` (types already checked; `i` at most the length).
fn put(stored: &mut Stored, i: usize, value: Owned) {
    fn at<T>(v: &mut Vec<T>, i: usize, x: T) {
        if i < v.len() {
            v[i] = x;
        } else {
            v.push(x);
        }
    }
    match (stored, value) {
        (Stored::Int(v), Owned::Int(x)) => at(v, i, x),
        (Stored::Double(v), Owned::Double(x)) => at(v, i, x),
        (Stored::String(v), Owned::String(x)) => at(v, i, x),
        (Stored::Pointer(v), Owned::Pointer(x)) => at(v, i, x),
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two instances' sets made from one template: a write, by the plugin or the host, is
    /// seen by the set written alone, the template and the other keep their values, and a
    /// string pointer handed out before the write still reads what it read.
    #[test]
    fn a_write_to_a_shared_set_is_its_own() {
        let log: Arc<Log> = Arc::default();
        let template = new_set(SetKind::EffectInst, "fx", "template", Some(log.clone()));
        let context = "OfxImageEffectPropContext";
        let data = "OfxPropInstanceData";
        template.set_str(
            b"OfxImageEffectPropContext\0",
            "OfxImageEffectContextFilter",
        );
        let (a, b) = (
            template.share("a".into(), Some(log.clone())),
            template.share("b".into(), Some(log.clone())),
        );
        let got = b.plugin_get("propGetString", context, PropType::String, 0);
        let Ok(One::String(before)) = got else {
            panic!("a string property: {got:?}");
        };
        a.set_str(
            b"OfxImageEffectPropContext\0",
            "OfxImageEffectContextGeneral",
        );
        // SAFETY: a pointer value, no string to read.
        unsafe { a.plugin_set("propSetPointer", data, 0, One::Pointer(0x1234)) }.unwrap();
        let string = |s: &PropSet| s.string(b"OfxImageEffectPropContext\0");
        assert_eq!(string(&a), "OfxImageEffectContextGeneral");
        assert_eq!(string(&b), "OfxImageEffectContextFilter");
        assert_eq!(string(&template), "OfxImageEffectContextFilter");
        let pointer = |s: &PropSet| s.get(data);
        assert_eq!(pointer(&a), Some(PropValue::Pointer(vec![0x1234])));
        assert_eq!(pointer(&b), Some(PropValue::Pointer(vec![0])));
        assert_eq!(
            a.all().get(context),
            Some(&PropValue::String(vec![
                "OfxImageEffectContextGeneral".into()
            ]))
        );
        assert_eq!(a.all().len(), b.all().len());
        // SAFETY: the pointer came from the shared entry, which the writes left in place.
        let still = unsafe { CStr::from_ptr(before) };
        assert_eq!(still.to_str(), Ok("OfxImageEffectContextFilter"));
        // A set made from a written one starts from its values.
        let c = a.share("c".into(), Some(log.clone()));
        assert_eq!(string(&c), "OfxImageEffectContextGeneral");
        assert!(log.violations().is_empty(), "{:?}", log.violations());
    }
}
