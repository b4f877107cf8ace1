//! torch checkpoints (`torch.save`, the zip format) read without Python: named tensors.
//!
//! **Container.** A zip archive whose entries share one folder (`<name>/`, the file's stem
//! at save time): `<name>/data.pkl` is the pickled object, `<name>/data/<key>` the raw bytes
//! of each storage (little-endian; `<name>/byteorder`, when present, says `little`).
//!
//! **Pickle.** `data.pkl` is a pickle (protocol 2 by default). A small stack machine runs
//! the opcodes a state dict uses (containers, numbers, strings, memo, `GLOBAL`, `REDUCE`,
//! `BUILD`, `BINPERSID`; protocol-4 framing is accepted too). Calls are *never* executed:
//! `REDUCE` knows `torch._utils._rebuild_tensor_v2(storage, offset, size, stride, …)`,
//! `torch._utils._rebuild_parameter(tensor, …)` and `collections.OrderedDict()`; any other
//! callable yields an opaque value (an optimiser's or scheduler's bookkeeping). A persistent
//! id `('storage', torch.<Type>Storage, key, location, numel)` is a storage of `numel`
//! elements of that type.
//!
//! **Result.** Nested dictionaries with string keys are flattened into dotted names
//! (`pipeline._model.field.mlp_base.model.params`), each naming a [`TensorInfo`] (dtype,
//! shape, stride, offset in elements); [`Checkpoint::read_f32`] gathers a float tensor's
//! elements in row-major order. Every malformed input is an [`Error`] naming the file and
//! the place (pickle byte offset, entry, tensor name), never a panic.

use std::cell::RefCell;
use std::collections::{BTreeMap, HashMap};
use std::path::Path;
use std::rc::Rc;

use half::f16;

use super::zip::Zip;
use crate::error::{Error, Result};

/// Element types of torch storages.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum DType {
    /// `torch.float32` (`FloatStorage`).
    F32,
    /// `torch.float16` (`HalfStorage`).
    F16,
    /// `torch.float64` (`DoubleStorage`).
    F64,
    /// `torch.bfloat16` (`BFloat16Storage`).
    BF16,
    /// `torch.int64` (`LongStorage`).
    I64,
    /// `torch.int32` (`IntStorage`).
    I32,
    /// `torch.int16` (`ShortStorage`).
    I16,
    /// `torch.int8` (`CharStorage`).
    I8,
    /// `torch.uint8` (`ByteStorage`).
    U8,
    /// `torch.bool` (`BoolStorage`).
    Bool,
}

impl DType {
    fn from_storage(name: &str) -> Option<Self> {
        Some(match name {
            "FloatStorage" => DType::F32,
            "HalfStorage" => DType::F16,
            "DoubleStorage" => DType::F64,
            "BFloat16Storage" => DType::BF16,
            "LongStorage" => DType::I64,
            "IntStorage" => DType::I32,
            "ShortStorage" => DType::I16,
            "CharStorage" => DType::I8,
            "ByteStorage" => DType::U8,
            "BoolStorage" => DType::Bool,
            _ => return None,
        })
    }

    /// Bytes per element.
    pub fn size(self) -> usize {
        match self {
            DType::F64 | DType::I64 => 8,
            DType::F32 | DType::I32 => 4,
            DType::F16 | DType::BF16 | DType::I16 => 2,
            DType::I8 | DType::U8 | DType::Bool => 1,
        }
    }
}

/// Where a tensor's elements are: a view of a storage.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct TensorInfo {
    /// Element type.
    pub(crate) dtype: DType,
    /// Sizes per dimension.
    pub shape: Vec<usize>,
    /// Strides per dimension, in elements.
    pub(crate) stride: Vec<usize>,
    /// First element in the storage.
    pub(crate) offset: usize,
    /// The storage's key (`data/<key>` in the archive).
    pub(crate) storage: String,
    /// Elements in the storage.
    pub(crate) storage_numel: usize,
}

impl TensorInfo {
    /// Number of elements (`Π shape`).
    pub(crate) fn numel(&self) -> usize {
        self.shape.iter().product()
    }
}

/// A torch checkpoint: its named tensors and the archive that holds their data.
#[derive(Debug)]
pub(crate) struct Checkpoint {
    zip: Zip,
    prefix: String,
    tensors: BTreeMap<String, TensorInfo>,
}

impl Checkpoint {
    /// Reads the archive at `path` and unpickles its `data.pkl`.
    pub fn open(path: &Path) -> Result<Self> {
        let zip = Zip::open(path)?;
        let pkl = zip
            .names()
            .find(|n| n.ends_with("/data.pkl") && n.matches('/').count() == 1)
            .map(str::to_owned)
            .ok_or_else(|| {
                Error::format(
                    path,
                    "",
                    "no '<name>/data.pkl' entry: not a torch checkpoint",
                )
            })?;
        let prefix = pkl.trim_end_matches("data.pkl").to_owned();
        if let Some(order) = zip.read(&format!("{prefix}byteorder"))? {
            if &*order != b"little" {
                return Err(Error::Unsupported(format!(
                    "{}: byte order '{}' (only little-endian checkpoints)",
                    path.display(),
                    String::from_utf8_lossy(&order)
                )));
            }
        }
        let bytes = zip.read(&pkl)?.unwrap_or_default();
        let root = Machine::new(path, &bytes).run()?;
        let mut tensors = BTreeMap::new();
        flatten(&root, "", &mut tensors);
        Ok(Checkpoint {
            zip,
            prefix,
            tensors,
        })
    }

    /// The checkpoint file.
    pub fn path(&self) -> &Path {
        self.zip.path()
    }

    /// The tensors by dotted name.
    pub(crate) fn tensors(&self) -> &BTreeMap<String, TensorInfo> {
        &self.tensors
    }

    /// The tensor `name`, if present.
    pub fn get(&self, name: &str) -> Option<&TensorInfo> {
        self.tensors.get(name)
    }

    /// The elements of the float tensor `name` (f32, f16, bf16 or f64) widened or rounded to
    /// f32, in row-major order of its shape.
    pub(crate) fn read_f32(&self, name: &str) -> Result<Vec<f32>> {
        let path = self.zip.path();
        let t = self
            .tensors
            .get(name)
            .ok_or_else(|| Error::format(path, name, "tensor missing from the checkpoint"))?;
        let entry = format!("{}data/{}", self.prefix, t.storage);
        let es = t.dtype.size();
        let needed = t.storage_numel as u64 * es as u64;
        let data = self.zip.read_at_most(&entry, needed)?.ok_or_else(|| {
            Error::format(path, name, format!("storage entry '{entry}' is missing"))
        })?;
        if (data.len() as u64) < needed {
            return Err(Error::format(
                path,
                name,
                format!(
                    "storage '{entry}' holds {} bytes, fewer than {} elements",
                    data.len(),
                    t.storage_numel
                ),
            ));
        }
        let widen: fn(&[u8]) -> f32 = match t.dtype {
            DType::F32 => |b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            DType::F16 => |b| f16::from_le_bytes([b[0], b[1]]).to_f32(),
            DType::BF16 => |b| f32::from_bits(u32::from(u16::from_le_bytes([b[0], b[1]])) << 16),
            DType::F64 => |b| {
                let mut a = [0u8; 8];
                a.copy_from_slice(&b[..8]);
                f64::from_le_bytes(a) as f32
            },
            other => {
                return Err(Error::format(
                    path,
                    name,
                    format!("expected a floating-point tensor, found {other:?}"),
                ))
            }
        };
        let n = t.numel();
        let mut out = Vec::with_capacity(n);
        let mut index = vec![0usize; t.shape.len()];
        for _ in 0..n {
            let e = t.offset
                + index
                    .iter()
                    .zip(&t.stride)
                    .map(|(i, s)| i * s)
                    .sum::<usize>();
            out.push(widen(&data[e * es..(e + 1) * es]));
            for d in (0..index.len()).rev() {
                index[d] += 1;
                if index[d] < t.shape[d] {
                    break;
                }
                index[d] = 0;
            }
        }
        Ok(out)
    }
}

/// Collects the tensors of nested string-keyed dictionaries under dotted names.
fn flatten(v: &Value, prefix: &str, out: &mut BTreeMap<String, TensorInfo>) {
    match v {
        Value::Tensor(t) => {
            out.insert(prefix.to_owned(), t.clone());
        }
        Value::Dict(d) => {
            for (k, v) in d.borrow().iter() {
                let key = match k {
                    Value::Str(s) => s.clone(),
                    Value::Int(i) => i.to_string(),
                    _ => continue,
                };
                let name = if prefix.is_empty() {
                    key
                } else {
                    format!("{prefix}.{key}")
                };
                flatten(v, &name, out);
            }
        }
        _ => {}
    }
}

/// A value on the pickle machine's stack.
#[derive(Clone, Debug)]
enum Value {
    None,
    Bool,
    Int(i64),
    Float,
    Str(String),
    Bytes,
    Tuple(Rc<Vec<Value>>),
    List(Rc<RefCell<Vec<Value>>>),
    Dict(Rc<RefCell<Vec<(Value, Value)>>>),
    /// A class or function named by `GLOBAL` (never imported, never called).
    Global(Rc<(String, String)>),
    /// A storage from a persistent id.
    Storage(Rc<(DType, String, usize)>),
    Tensor(TensorInfo),
    /// The result of a call the machine does not model.
    Opaque,
    /// The stack marker of `MARK`.
    Mark,
}

impl Value {
    fn kind(&self) -> &'static str {
        match self {
            Value::None => "None",
            Value::Bool => "bool",
            Value::Int(_) => "int",
            Value::Float => "float",
            Value::Str(_) => "str",
            Value::Bytes => "bytes",
            Value::Tuple(_) => "tuple",
            Value::List(_) => "list",
            Value::Dict(_) => "dict",
            Value::Global(_) => "global",
            Value::Storage(_) => "storage",
            Value::Tensor(_) => "tensor",
            Value::Opaque => "object",
            Value::Mark => "mark",
        }
    }
}

/// The pickle stack machine over one `data.pkl`.
struct Machine<'a> {
    path: &'a Path,
    bytes: &'a [u8],
    pos: usize,
    /// Offset of the opcode being run (for messages).
    op_at: usize,
    stack: Vec<Value>,
    memo: HashMap<u32, Value>,
}

impl<'a> Machine<'a> {
    fn new(path: &'a Path, bytes: &'a [u8]) -> Self {
        Machine {
            path,
            bytes,
            pos: 0,
            op_at: 0,
            stack: Vec::new(),
            memo: HashMap::new(),
        }
    }

    fn err(&self, msg: impl Into<String>) -> Error {
        Error::format(
            self.path,
            format!("data.pkl byte {}", self.op_at),
            msg.into(),
        )
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8]> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.bytes.len());
        let Some(end) = end else {
            return Err(self.err("pickle truncated"));
        };
        let s = &self.bytes[self.pos..end];
        self.pos = end;
        Ok(s)
    }

    fn u8(&mut self) -> Result<u8> {
        Ok(self.take(1)?[0])
    }

    fn u16(&mut self) -> Result<u16> {
        let b = self.take(2)?;
        Ok(u16::from_le_bytes([b[0], b[1]]))
    }

    fn u32(&mut self) -> Result<u32> {
        let b = self.take(4)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    fn line(&mut self) -> Result<String> {
        let rest = &self.bytes[self.pos.min(self.bytes.len())..];
        let n = rest
            .iter()
            .position(|&b| b == b'\n')
            .ok_or_else(|| self.err("pickle truncated inside a GLOBAL name"))?;
        let s = String::from_utf8(rest[..n].to_vec())
            .map_err(|_| self.err("GLOBAL name is not UTF-8"))?;
        self.pos += n + 1;
        Ok(s)
    }

    fn utf8(&mut self, n: usize) -> Result<Value> {
        let b = self.take(n)?;
        String::from_utf8(b.to_vec())
            .map(Value::Str)
            .map_err(|_| self.err("string is not UTF-8"))
    }

    fn pop(&mut self) -> Result<Value> {
        match self.stack.pop() {
            Some(Value::Mark) | None => Err(self.err("pickle stack underflow")),
            Some(v) => Ok(v),
        }
    }

    fn top(&self) -> Result<&Value> {
        match self.stack.last() {
            Some(Value::Mark) | None => Err(self.err("pickle stack underflow")),
            Some(v) => Ok(v),
        }
    }

    /// The values above the topmost mark, removing them and the mark.
    fn pop_mark(&mut self) -> Result<Vec<Value>> {
        let at = self
            .stack
            .iter()
            .rposition(|v| matches!(v, Value::Mark))
            .ok_or_else(|| self.err("no MARK on the pickle stack"))?;
        let items = self.stack.split_off(at + 1);
        self.stack.pop();
        Ok(items)
    }

    fn push(&mut self, v: Value) {
        self.stack.push(v);
    }

    fn memo_put(&mut self, key: u32) -> Result<()> {
        let v = self.top()?.clone();
        self.memo.insert(key, v);
        Ok(())
    }

    fn memo_get(&mut self, key: u32) -> Result<()> {
        let v = self
            .memo
            .get(&key)
            .cloned()
            .ok_or_else(|| self.err(format!("memo entry {key} is not set")))?;
        self.push(v);
        Ok(())
    }

    fn set_items(&self, target: &Value, items: Vec<Value>) -> Result<()> {
        let Value::Dict(d) = target else {
            return Err(self.err(format!("SETITEMS on a {}", target.kind())));
        };
        if !items.len().is_multiple_of(2) {
            return Err(self.err("SETITEMS with an odd number of values"));
        }
        let mut d = d.borrow_mut();
        let mut it = items.into_iter();
        while let (Some(k), Some(v)) = (it.next(), it.next()) {
            d.push((k, v));
        }
        Ok(())
    }

    fn append(&self, target: &Value, items: Vec<Value>) -> Result<()> {
        match target {
            Value::List(l) => {
                l.borrow_mut().extend(items);
                Ok(())
            }
            other => Err(self.err(format!("APPEND on a {}", other.kind()))),
        }
    }

    /// Runs to `STOP` and returns the object.
    fn run(mut self) -> Result<Value> {
        loop {
            self.op_at = self.pos;
            let op = self.u8()?;
            match op {
                0x80 => {
                    let proto = self.u8()?;
                    if proto > 5 {
                        return Err(self.err(format!("unknown pickle protocol {proto}")));
                    }
                }
                0x95 => {
                    self.take(8)?;
                }
                b'.' => {
                    let v = self.pop()?;
                    return Ok(v);
                }
                b'(' => self.push(Value::Mark),
                b'N' => self.push(Value::None),
                0x88 | 0x89 => self.push(Value::Bool),
                b'K' => {
                    let v = self.u8()?;
                    self.push(Value::Int(i64::from(v)));
                }
                b'M' => {
                    let v = self.u16()?;
                    self.push(Value::Int(i64::from(v)));
                }
                b'J' => {
                    let v = self.u32()? as i32;
                    self.push(Value::Int(i64::from(v)));
                }
                0x8a => {
                    let n = usize::from(self.u8()?);
                    let b = self.take(n)?;
                    if n > 8 {
                        self.push(Value::Opaque);
                    } else {
                        let neg = b.last().is_some_and(|&x| x & 0x80 != 0);
                        let mut a = [if neg { 0xFF } else { 0 }; 8];
                        a[..n].copy_from_slice(b);
                        self.push(Value::Int(i64::from_le_bytes(a)));
                    }
                }
                b'G' => {
                    self.take(8)?;
                    self.push(Value::Float);
                }
                b'X' => {
                    let n = self.u32()? as usize;
                    let v = self.utf8(n)?;
                    self.push(v);
                }
                0x8c => {
                    let n = usize::from(self.u8()?);
                    let v = self.utf8(n)?;
                    self.push(v);
                }
                b'T' | b'B' => {
                    let n = self.u32()? as usize;
                    self.take(n)?;
                    self.push(Value::Bytes);
                }
                b'U' | b'C' => {
                    let n = usize::from(self.u8()?);
                    self.take(n)?;
                    self.push(Value::Bytes);
                }
                b')' => self.push(Value::Tuple(Rc::new(Vec::new()))),
                b't' => {
                    let items = self.pop_mark()?;
                    self.push(Value::Tuple(Rc::new(items)));
                }
                0x85..=0x87 => {
                    let n = usize::from(op - 0x84);
                    if self.stack.len() < n {
                        return Err(self.err("pickle stack underflow"));
                    }
                    let mut items = Vec::with_capacity(n);
                    for _ in 0..n {
                        items.push(self.pop()?);
                    }
                    items.reverse();
                    self.push(Value::Tuple(Rc::new(items)));
                }
                b']' => self.push(Value::List(Rc::default())),
                b'l' => {
                    let items = self.pop_mark()?;
                    self.push(Value::List(Rc::new(RefCell::new(items))));
                }
                b'}' => self.push(Value::Dict(Rc::default())),
                b'd' => {
                    let items = self.pop_mark()?;
                    let d = Value::Dict(Rc::default());
                    self.set_items(&d, items)?;
                    self.push(d);
                }
                b'a' => {
                    let v = self.pop()?;
                    let target = self.top()?.clone();
                    self.append(&target, vec![v])?;
                }
                b'e' => {
                    let items = self.pop_mark()?;
                    let target = self.top()?.clone();
                    self.append(&target, items)?;
                }
                b's' => {
                    let v = self.pop()?;
                    let k = self.pop()?;
                    let target = self.top()?.clone();
                    self.set_items(&target, vec![k, v])?;
                }
                b'u' => {
                    let items = self.pop_mark()?;
                    let target = self.top()?.clone();
                    self.set_items(&target, items)?;
                }
                b'q' => {
                    let k = u32::from(self.u8()?);
                    self.memo_put(k)?;
                }
                b'r' => {
                    let k = self.u32()?;
                    self.memo_put(k)?;
                }
                0x94 => {
                    let k = self.memo.len() as u32;
                    self.memo_put(k)?;
                }
                b'h' => {
                    let k = u32::from(self.u8()?);
                    self.memo_get(k)?;
                }
                b'j' => {
                    let k = self.u32()?;
                    self.memo_get(k)?;
                }
                b'0' => {
                    self.pop()?;
                }
                b'1' => {
                    self.pop_mark()?;
                }
                b'2' => {
                    let v = self.top()?.clone();
                    self.push(v);
                }
                b'c' => {
                    let module = self.line()?;
                    let name = self.line()?;
                    self.push(Value::Global(Rc::new((module, name))));
                }
                0x93 => {
                    let name = self.pop()?;
                    let module = self.pop()?;
                    match (module, name) {
                        (Value::Str(m), Value::Str(n)) => {
                            self.push(Value::Global(Rc::new((m, n))));
                        }
                        _ => return Err(self.err("STACK_GLOBAL needs two strings")),
                    }
                }
                b'Q' => {
                    let pid = self.pop()?;
                    let storage = self.persistent(&pid)?;
                    self.push(storage);
                }
                b'R' => {
                    let args = self.pop()?;
                    let func = self.pop()?;
                    let v = self.reduce(&func, &args)?;
                    self.push(v);
                }
                0x81 => {
                    self.pop()?;
                    self.pop()?;
                    self.push(Value::Opaque);
                }
                b'b' => {
                    // BUILD sets an object's state: a state dict's `_metadata`, an object's
                    // attributes; nothing a tensor depends on.
                    self.pop()?;
                    self.top()?;
                }
                other => {
                    return Err(self.err(format!(
                        "unsupported pickle opcode 0x{other:02x}: corrupt or not a torch \
                         checkpoint"
                    )))
                }
            }
        }
    }

    /// A storage from the persistent id `('storage', type, key, location, numel)`.
    fn persistent(&self, pid: &Value) -> Result<Value> {
        let bad = || self.err("persistent id is not ('storage', type, key, location, numel)");
        let Value::Tuple(t) = pid else {
            return Err(bad());
        };
        match t.as_slice() {
            [Value::Str(tag), Value::Global(ty), Value::Str(key), _, Value::Int(numel)]
                if tag == "storage" && *numel >= 0 =>
            {
                let dtype = DType::from_storage(&ty.1)
                    .filter(|_| ty.0 == "torch")
                    .ok_or_else(|| self.err(format!("unknown storage type {}.{}", ty.0, ty.1)))?;
                Ok(Value::Storage(Rc::new((
                    dtype,
                    key.clone(),
                    *numel as usize,
                ))))
            }
            _ => Err(bad()),
        }
    }

    /// `func(*args)` for the callables a state dict uses; others give an opaque value.
    fn reduce(&self, func: &Value, args: &Value) -> Result<Value> {
        let Value::Global(g) = func else {
            return Err(self.err(format!("REDUCE calls a {}", func.kind())));
        };
        let Value::Tuple(args) = args else {
            return Err(self.err("REDUCE arguments are not a tuple"));
        };
        match (g.0.as_str(), g.1.as_str()) {
            ("torch._utils", "_rebuild_tensor_v2") => self.rebuild_tensor(args),
            ("torch._utils", "_rebuild_parameter") => match args.first() {
                Some(t @ Value::Tensor(_)) => Ok(t.clone()),
                _ => Err(self.err("_rebuild_parameter without a tensor")),
            },
            ("collections", "OrderedDict") => {
                let d = Value::Dict(Rc::default());
                if let Some(Value::List(pairs)) = args.first() {
                    for p in pairs.borrow().iter() {
                        match p {
                            Value::Tuple(kv) if kv.len() == 2 => {
                                self.set_items(&d, kv.to_vec())?;
                            }
                            _ => return Err(self.err("OrderedDict item is not a pair")),
                        }
                    }
                }
                Ok(d)
            }
            _ => Ok(Value::Opaque),
        }
    }

    /// `_rebuild_tensor_v2(storage, offset, size, stride, requires_grad, hooks[, metadata])`.
    fn rebuild_tensor(&self, args: &[Value]) -> Result<Value> {
        let ints = |v: &Value, what: &str| -> Result<Vec<usize>> {
            match v {
                Value::Tuple(t) => t
                    .iter()
                    .map(|x| match x {
                        Value::Int(i) if *i >= 0 => Ok(*i as usize),
                        _ => Err(self.err(format!("tensor {what} is not a tuple of counts"))),
                    })
                    .collect(),
                _ => Err(self.err(format!("tensor {what} is not a tuple"))),
            }
        };
        let (Some(Value::Storage(s)), Some(Value::Int(offset)), Some(size), Some(stride)) =
            (args.first(), args.get(1), args.get(2), args.get(3))
        else {
            return Err(self
                .err("_rebuild_tensor_v2 arguments are not (storage, offset, size, stride, ...)"));
        };
        let (shape, stride) = (ints(size, "size")?, ints(stride, "stride")?);
        if shape.len() != stride.len() || *offset < 0 {
            return Err(self.err("tensor size and stride disagree"));
        }
        let offset = *offset as usize;
        // The last element touched must lie inside the storage.
        if shape.iter().all(|&n| n > 0) {
            let last = shape.iter().zip(&stride).try_fold(offset, |acc, (&n, &s)| {
                (n - 1).checked_mul(s).and_then(|x| acc.checked_add(x))
            });
            if last.is_none_or(|l| l >= s.2) {
                return Err(self.err(format!(
                    "tensor of shape {shape:?} (stride {stride:?}, offset {offset}) does not \
                     fit its storage of {} elements",
                    s.2
                )));
            }
        }
        // Each element is read into memory: never more than the storage really holds.
        let numel = shape.iter().try_fold(1usize, |a, &n| a.checked_mul(n));
        if numel.is_none_or(|n| n > s.2) {
            return Err(self.err(format!(
                "tensor of shape {shape:?} has more elements than its storage of {} (a view \
                 that repeats elements is not a saved parameter)",
                s.2
            )));
        }
        Ok(Value::Tensor(TensorInfo {
            dtype: s.0,
            shape,
            stride,
            offset,
            storage: s.1.clone(),
            storage_numel: s.2,
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Opcode bytes written out from the pickle format (protocol 2), independently of the
    /// machine: `{'a': {'w': tensor[2x3] (FloatStorage '0', offset 1, stride (1, 2))},
    /// 'step': 7, 'lr': 0.5, 'ok': True}`, the storage holding 0, 1, …, 7.
    fn pickle() -> Vec<u8> {
        let mut p = vec![0x80, 2, b'}', b'q', 0, b'('];
        let s = |p: &mut Vec<u8>, t: &str| {
            p.push(b'X');
            p.extend((t.len() as u32).to_le_bytes());
            p.extend(t.as_bytes());
        };
        s(&mut p, "a");
        p.extend(b"ccollections\nOrderedDict\nq\x01)R");
        s(&mut p, "w");
        p.extend(b"ctorch._utils\n_rebuild_tensor_v2\n(");
        p.push(b'(');
        s(&mut p, "storage");
        p.extend(b"ctorch\nFloatStorage\n");
        s(&mut p, "0");
        s(&mut p, "cpu");
        p.extend([
            b'K', 8, b't', b'Q', b'K', 1, b'K', 2, b'K', 3, 0x86, b'K', 1, b'K', 2, 0x86,
        ]);
        p.extend([0x89, b'h', 1, b')', b'R', b't', b'R', b's']);
        s(&mut p, "step");
        p.extend([b'K', 7]);
        s(&mut p, "lr");
        p.push(b'G');
        p.extend(0.5f64.to_be_bytes());
        s(&mut p, "ok");
        p.extend([0x88, b'u', b'.']);
        p
    }

    #[test]
    fn a_view_holding_more_elements_than_its_storage_is_refused() {
        // Shape 20 x 30 with strides 0 over a storage of 8: 600 elements read from 8.
        let mut bytes = pickle();
        let shape = [b'K', 2, b'K', 3, 0x86, b'K', 1, b'K', 2, 0x86];
        let at = bytes.windows(shape.len()).position(|w| w == shape).unwrap();
        bytes[at..at + shape.len()]
            .copy_from_slice(&[b'K', 20, b'K', 30, 0x86, b'K', 0, b'K', 0, 0x86]);
        let e = Machine::new(Path::new("t.ckpt"), &bytes)
            .run()
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("t.ckpt") && e.contains("more elements than its storage of 8"),
            "{e}"
        );
    }

    #[test]
    fn unpickles_a_nested_state_dict() {
        let bytes = pickle();
        let root = Machine::new(Path::new("t.ckpt"), &bytes).run().unwrap();
        let mut t = BTreeMap::new();
        flatten(&root, "", &mut t);
        assert_eq!(t.len(), 1);
        let w = &t["a.w"];
        assert_eq!(
            (w.dtype, &w.shape[..], &w.stride[..], w.offset),
            (DType::F32, &[2usize, 3][..], &[1usize, 2][..], 1)
        );
        assert_eq!((w.storage.as_str(), w.storage_numel), ("0", 8));
    }

    #[test]
    fn every_truncation_and_bad_opcode_is_an_error() {
        let bytes = pickle();
        for cut in 0..bytes.len() {
            let e = Machine::new(Path::new("t.ckpt"), &bytes[..cut])
                .run()
                .expect_err("truncated pickle accepted")
                .to_string();
            assert!(e.contains("t.ckpt") && e.contains("data.pkl byte"), "{e}");
        }
        for at in 0..bytes.len() {
            for flip in [0x01u8, 0x40, 0xFF] {
                let mut b = bytes.clone();
                b[at] ^= flip;
                // Any outcome but a panic; errors name the file.
                if let Err(e) = Machine::new(Path::new("t.ckpt"), &b).run() {
                    assert!(e.to_string().contains("t.ckpt"));
                }
            }
        }
    }

    #[test]
    fn a_tensor_outside_its_storage_is_refused() {
        let mut bytes = pickle();
        // numel 8 → 6: offset 1 + (1·1 + 2·2) = 6 is then out of range.
        let at = bytes.windows(3).position(|w| w == [b'K', 8, b't']).unwrap();
        bytes[at + 1] = 6;
        let e = Machine::new(Path::new("t.ckpt"), &bytes).run().unwrap_err();
        assert!(e.to_string().contains("does not fit"), "{e}");
    }
}
