//! A bounded reader for Python pickles (protocols 0-5), enough for `torch.save` files.
//!
//! It builds a tree of plain values and never executes anything: globals stay names
//! ([`Value::Global`]), calls stay unevaluated ([`Value::Reduce`], [`Value::Build`]).
//! Every resource a hostile stream could exhaust is bounded by [`Limits`]:
//! - work: each opcode costs 1 and each element copied costs 1 ([`Limits::max_work`]);
//! - memory: every value allocated counts one node, every byte of a string counts one
//!   byte ([`Limits::max_nodes`], [`Limits::max_bytes`]);
//! - depth: every value knows its nesting depth, and nothing deeper than
//!   [`Limits::max_depth`] is built, so walking or dropping a tree cannot overflow the stack.
//!
//! Memo entries share their value (`Rc`), so `GET` costs O(1) whatever it refers to; a
//! container changed after it was memoised is copied first (copy on write), and that copy
//! is charged element by element. Python would mutate the shared object instead: a
//! difference that only shows in pickles that memoise a container and fetch it back
//! after changing it, which `torch.save` never writes.

use std::rc::Rc;

/// Every pickle opcode by its name in Python's `pickletools` (protocol 0 text opcodes are
/// their ASCII letters). Those the reader refuses (extension registry, class instances by
/// name, out-of-band buffers) are named too, so that each byte the format defines is named
/// here once.
pub(crate) mod op {
    // Protocol 0 and 1.
    pub const MARK: u8 = b'(';
    pub const STOP: u8 = b'.';
    pub const POP: u8 = b'0';
    pub const POP_MARK: u8 = b'1';
    pub const DUP: u8 = b'2';
    pub const FLOAT: u8 = b'F';
    pub const INT: u8 = b'I';
    pub const BININT: u8 = b'J';
    pub const BININT1: u8 = b'K';
    pub const LONG: u8 = b'L';
    pub const BININT2: u8 = b'M';
    pub const NONE: u8 = b'N';
    pub const PERSID: u8 = b'P';
    pub const BINPERSID: u8 = b'Q';
    pub const REDUCE: u8 = b'R';
    pub const STRING: u8 = b'S';
    pub const BINSTRING: u8 = b'T';
    pub const SHORT_BINSTRING: u8 = b'U';
    pub const UNICODE: u8 = b'V';
    pub const BINUNICODE: u8 = b'X';
    pub const APPEND: u8 = b'a';
    pub const BUILD: u8 = b'b';
    pub const GLOBAL: u8 = b'c';
    pub const DICT: u8 = b'd';
    pub const EMPTY_DICT: u8 = b'}';
    pub const APPENDS: u8 = b'e';
    pub const GET: u8 = b'g';
    pub const BINGET: u8 = b'h';
    #[cfg_attr(not(test), allow(dead_code))]
    pub const INST: u8 = b'i';
    pub const LONG_BINGET: u8 = b'j';
    pub const LIST: u8 = b'l';
    pub const EMPTY_LIST: u8 = b']';
    #[cfg_attr(not(test), allow(dead_code))]
    pub const OBJ: u8 = b'o';
    pub const PUT: u8 = b'p';
    pub const BINPUT: u8 = b'q';
    pub const LONG_BINPUT: u8 = b'r';
    pub const SETITEM: u8 = b's';
    pub const TUPLE: u8 = b't';
    pub const EMPTY_TUPLE: u8 = b')';
    pub const SETITEMS: u8 = b'u';
    pub const BINFLOAT: u8 = b'G';
    // Protocol 2.
    pub const PROTO: u8 = 0x80;
    pub const NEWOBJ: u8 = 0x81;
    #[cfg_attr(not(test), allow(dead_code))]
    pub const EXT1: u8 = 0x82;
    #[cfg_attr(not(test), allow(dead_code))]
    pub const EXT2: u8 = 0x83;
    #[cfg_attr(not(test), allow(dead_code))]
    pub const EXT4: u8 = 0x84;
    pub const TUPLE1: u8 = 0x85;
    pub const TUPLE2: u8 = 0x86;
    pub const TUPLE3: u8 = 0x87;
    pub const NEWTRUE: u8 = 0x88;
    pub const NEWFALSE: u8 = 0x89;
    pub const LONG1: u8 = 0x8a;
    pub const LONG4: u8 = 0x8b;
    // Protocol 3.
    pub const BINBYTES: u8 = b'B';
    pub const SHORT_BINBYTES: u8 = b'C';
    // Protocol 4.
    pub const SHORT_BINUNICODE: u8 = 0x8c;
    pub const BINUNICODE8: u8 = 0x8d;
    pub const BINBYTES8: u8 = 0x8e;
    pub const EMPTY_SET: u8 = 0x8f;
    pub const ADDITEMS: u8 = 0x90;
    pub const FROZENSET: u8 = 0x91;
    pub const NEWOBJ_EX: u8 = 0x92;
    pub const STACK_GLOBAL: u8 = 0x93;
    pub const MEMOIZE: u8 = 0x94;
    pub const FRAME: u8 = 0x95;
    // Protocol 5.
    pub const BYTEARRAY8: u8 = 0x96;
    #[cfg_attr(not(test), allow(dead_code))]
    pub const NEXT_BUFFER: u8 = 0x97;
    #[cfg_attr(not(test), allow(dead_code))]
    pub const READONLY_BUFFER: u8 = 0x98;
}

/// Resource bounds for one stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// Opcodes run plus elements copied.
    pub max_work: u64,
    /// Values allocated.
    pub max_nodes: u64,
    /// Bytes of strings and byte strings allocated.
    pub max_bytes: u64,
    /// Nesting depth of any value.
    pub max_depth: u32,
    /// Values on the stack plus memo entries.
    pub max_live: usize,
}

impl Default for Limits {
    /// Far above what a CamPro checkpoint needs (a few hundred opcodes), far below what
    /// hurts: about 100 MB at most.
    fn default() -> Self {
        Self { max_work: 2_000_000, max_nodes: 1_000_000, max_bytes: 16 << 20, max_depth: 64, max_live: 100_000 }
    }
}

/// A value of the pickle.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    /// `None`.
    None,
    /// `True` / `False`.
    Bool(bool),
    /// An integer that fits 64 bits.
    Int(i64),
    /// An integer that does not fit 64 bits (its little-endian two's complement bytes).
    BigInt(Rc<[u8]>),
    /// A float.
    Float(f64),
    /// A text string.
    Str(Rc<str>),
    /// A byte string.
    Bytes(Rc<[u8]>),
    /// A tuple.
    Tuple(Node),
    /// A list.
    List(Node),
    /// A dict, in insertion order.
    Dict(Node),
    /// A set or frozenset (its items).
    Set(Node),
    /// A global `module.name`, never imported.
    Global {
        /// The module.
        module: Rc<str>,
        /// The name in it.
        name: Rc<str>,
    },
    /// `callable(*args)`, not called: both in `items` (callable first, then the args tuple).
    Reduce(Node),
    /// `obj.__setstate__(state)`, not run: `items` holds the object, then the state.
    Build(Node),
    /// A persistent id (torch: a storage reference).
    PersistentId(Node),
}

/// The children of a container value, shared, with the container's nesting depth. A
/// dict's items alternate key and value.
#[derive(Debug, Clone, PartialEq)]
pub struct Node {
    /// Nesting depth (1 for a container of scalars).
    pub depth: u32,
    /// The items.
    pub items: Rc<Vec<Value>>,
}

impl Value {
    /// The children of a container value; `None` for scalars and globals.
    pub fn node(&self) -> Option<&Node> {
        match self {
            Value::Tuple(n)
            | Value::List(n)
            | Value::Dict(n)
            | Value::Set(n)
            | Value::Reduce(n)
            | Value::Build(n)
            | Value::PersistentId(n) => Some(n),
            _ => None,
        }
    }

    /// Nesting depth: 0 for scalars.
    pub fn depth(&self) -> u32 {
        self.node().map_or(0, |n| n.depth)
    }

    /// The items of a tuple or list.
    pub fn as_seq(&self) -> Option<&[Value]> {
        match self {
            Value::Tuple(n) | Value::List(n) => Some(&n.items),
            _ => None,
        }
    }

    /// The (key, value) pairs of a dict.
    pub fn as_dict(&self) -> Option<impl Iterator<Item = (&Value, &Value)>> {
        match self {
            Value::Dict(n) => Some(n.items.chunks_exact(2).map(|kv| (&kv[0], &kv[1]))),
            _ => None,
        }
    }

    /// A text string.
    pub fn as_str(&self) -> Option<&str> {
        match self {
            Value::Str(s) => Some(s),
            _ => None,
        }
    }

    /// An integer.
    pub fn as_int(&self) -> Option<i64> {
        match self {
            Value::Int(v) => Some(*v),
            Value::Bool(b) => Some(*b as i64),
            _ => None,
        }
    }

    /// Whether this is the global `module.name`.
    pub fn is_global(&self, m: &str, n: &str) -> bool {
        matches!(self, Value::Global { module, name } if &**module == m && &**name == n)
    }

    /// Every global named anywhere in the value. Shared containers (memo fetches) are
    /// visited once, so the walk costs the number of distinct containers, not the size of
    /// the tree they unfold to (which doubling fetches make exponential).
    pub fn globals(&self) -> Vec<(&str, &str)> {
        let mut out = Vec::new();
        let mut seen = std::collections::HashSet::new();
        let mut todo = vec![self];
        while let Some(v) = todo.pop() {
            if let Value::Global { module, name } = v {
                out.push((&**module, &**name));
            } else if let Some(n) = v.node().filter(|n| seen.insert(Rc::as_ptr(&n.items))) {
                todo.extend(n.items.iter());
            }
        }
        out
    }

    /// What kind of value this is, in words (for errors).
    pub fn kind(&self) -> &'static str {
        match self {
            Value::None => "None",
            Value::Bool(_) => "a bool",
            Value::Int(_) | Value::BigInt(_) => "an integer",
            Value::Float(_) => "a float",
            Value::Str(_) => "a string",
            Value::Bytes(_) => "bytes",
            Value::Tuple(_) => "a tuple",
            Value::List(_) => "a list",
            Value::Dict(_) => "a dict",
            Value::Set(_) => "a set",
            Value::Global { .. } => "a global",
            Value::Reduce(_) => "a call",
            Value::Build(_) => "a build call",
            Value::PersistentId(_) => "a persistent reference",
        }
    }
}

/// Why a stream was refused; `at` is the byte offset of the opcode.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum PickleError {
    /// The stream is malformed.
    #[error("byte {at}: {what}")]
    Malformed {
        /// Offset of the opcode.
        at: usize,
        /// What is wrong.
        what: String,
    },
    /// A resource bound was reached.
    #[error("byte {at}: the pickle needs more than {limit} {what}")]
    Limit {
        /// Offset of the opcode.
        at: usize,
        /// Which resource.
        what: &'static str,
        /// The bound.
        limit: u64,
    },
}

/// One stack slot: a value or a MARK.
enum Slot {
    Mark,
    Val(Value),
}

struct Vm<'a> {
    data: &'a [u8],
    pos: usize,
    at: usize,
    lim: Limits,
    work: u64,
    nodes: u64,
    bytes: u64,
    stack: Vec<Slot>,
    memo: std::collections::HashMap<u64, Value>,
}

/// Reads one pickle from `data` (up to its STOP) within `limits`.
pub fn read(data: &[u8], limits: Limits) -> Result<Value, PickleError> {
    read_prefix(data, limits).map(|(v, _)| v)
}

/// Reads the pickle at the start of `data` within `limits`; returns it and the bytes it
/// took (up to and including its STOP), for streams of several pickles.
pub fn read_prefix(data: &[u8], limits: Limits) -> Result<(Value, usize), PickleError> {
    let mut vm = Vm {
        data,
        pos: 0,
        at: 0,
        lim: limits,
        work: 0,
        nodes: 0,
        bytes: 0,
        stack: Vec::new(),
        memo: Default::default(),
    };
    let v = vm.run()?;
    Ok((v, vm.pos))
}

impl<'a> Vm<'a> {
    fn bad<T>(&self, what: impl Into<String>) -> Result<T, PickleError> {
        Err(PickleError::Malformed { at: self.at, what: what.into() })
    }

    fn limit(&self, what: &'static str, limit: u64) -> PickleError {
        PickleError::Limit { at: self.at, what, limit }
    }

    fn charge_work(&mut self, n: u64) -> Result<(), PickleError> {
        self.work += n;
        if self.work > self.lim.max_work {
            return Err(self.limit("steps of work", self.lim.max_work));
        }
        Ok(())
    }

    fn charge_nodes(&mut self, n: u64) -> Result<(), PickleError> {
        self.nodes += n;
        if self.nodes > self.lim.max_nodes {
            return Err(self.limit("values", self.lim.max_nodes));
        }
        Ok(())
    }

    fn charge_bytes(&mut self, n: u64) -> Result<(), PickleError> {
        self.bytes += n;
        if self.bytes > self.lim.max_bytes {
            return Err(self.limit("bytes of strings", self.lim.max_bytes));
        }
        Ok(())
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8], PickleError> {
        match self.data.get(self.pos..self.pos.saturating_add(n)) {
            Some(s) if self.pos.checked_add(n).is_some() => {
                self.pos += n;
                Ok(s)
            }
            _ => self.bad("the stream ends inside an opcode"),
        }
    }

    fn u8(&mut self) -> Result<u8, PickleError> {
        Ok(self.take(1)?[0])
    }

    fn le(&mut self, n: usize) -> Result<u64, PickleError> {
        let b = self.take(n)?;
        Ok(b.iter().rev().fold(0u64, |a, &x| (a << 8) | x as u64))
    }

    fn line(&mut self) -> Result<&'a str, PickleError> {
        let rest = &self.data[self.pos.min(self.data.len())..];
        let Some(end) = rest.iter().position(|&b| b == b'\n') else {
            return self.bad("a text argument has no end of line");
        };
        self.pos += end + 1;
        std::str::from_utf8(&rest[..end]).or_else(|_| self.bad("a text argument is not UTF-8"))
    }

    /// Refuses one more value on the stack or in the memo past [`Limits::max_live`].
    fn room_for_one_more(&self) -> Result<(), PickleError> {
        if self.stack.len() + self.memo.len() >= self.lim.max_live {
            return Err(self.limit("live values", self.lim.max_live as u64));
        }
        Ok(())
    }

    fn push(&mut self, v: Value) -> Result<(), PickleError> {
        if v.depth() > self.lim.max_depth {
            return Err(self.limit("levels of nesting", self.lim.max_depth as u64));
        }
        self.room_for_one_more()?;
        self.stack.push(Slot::Val(v));
        Ok(())
    }

    fn pop(&mut self) -> Result<Value, PickleError> {
        match self.stack.pop() {
            Some(Slot::Val(v)) => Ok(v),
            Some(Slot::Mark) => self.bad("a MARK where a value was expected"),
            None => self.bad("the stack is empty"),
        }
    }

    fn top(&mut self) -> Result<&mut Value, PickleError> {
        match self.stack.last_mut() {
            Some(Slot::Val(v)) => Ok(v),
            _ => Err(PickleError::Malformed { at: self.at, what: "no value on top of the stack".into() }),
        }
    }

    /// The values above the topmost MARK, which is removed.
    fn pop_mark(&mut self) -> Result<Vec<Value>, PickleError> {
        let Some(m) = self.stack.iter().rposition(|s| matches!(s, Slot::Mark)) else { return self.bad("no MARK") };
        let items = self.stack.split_off(m + 1);
        self.stack.pop();
        Ok(items
            .into_iter()
            .map(|s| if let Slot::Val(v) = s { v } else { unreachable!("above the topmost MARK") })
            .collect())
    }

    fn node(&mut self, items: Vec<Value>) -> Result<Node, PickleError> {
        self.charge_nodes(1 + items.len() as u64)?;
        let depth = 1 + items.iter().map(Value::depth).max().unwrap_or(0);
        Ok(Node { depth, items: Rc::new(items) })
    }

    fn string(&mut self, b: &[u8]) -> Result<Value, PickleError> {
        self.charge_bytes(b.len() as u64)?;
        let s = std::str::from_utf8(b).or_else(|_| self.bad("a string is not UTF-8"))?;
        Ok(Value::Str(s.into()))
    }

    fn bytes_value(&mut self, b: &[u8]) -> Result<Value, PickleError> {
        self.charge_bytes(b.len() as u64)?;
        Ok(Value::Bytes(b.into()))
    }

    fn long(&mut self, b: &[u8]) -> Result<Value, PickleError> {
        self.charge_bytes(b.len() as u64)?;
        if b.len() <= 8 {
            let neg = b.last().is_some_and(|&x| x & 0x80 != 0);
            let mut v: u64 = if neg { u64::MAX } else { 0 };
            for (i, &x) in b.iter().enumerate() {
                v &= !(0xffu64 << (8 * i));
                v |= (x as u64) << (8 * i);
            }
            Ok(Value::Int(v as i64))
        } else {
            Ok(Value::BigInt(b.into()))
        }
    }

    /// Adds the pairs / items to the container on top of the stack (copying it first if
    /// it is shared with the memo), charging every element copied or added.
    fn extend_top(&mut self, added: Vec<Value>, want: &str) -> Result<(), PickleError> {
        let at = self.at;
        let max_depth = self.lim.max_depth;
        let added_depth = added.iter().map(Value::depth).max().unwrap_or(0);
        let top = self.top()?;
        let node = match top {
            Value::Dict(n) if want == "dict" => n,
            Value::List(n) if want == "list" => n,
            Value::Set(n) if want == "set" => n,
            other => {
                let kind = other.kind();
                return Err(PickleError::Malformed {
                    at,
                    what: format!("expected a {want} on the stack, found {kind}"),
                });
            }
        };
        let copied = if Rc::strong_count(&node.items) > 1 { node.items.len() as u64 } else { 0 };
        let new_depth = node.depth.max(added_depth + 1);
        if new_depth > max_depth {
            return Err(PickleError::Limit { at, what: "levels of nesting", limit: max_depth as u64 });
        }
        let n_added = added.len() as u64;
        node.depth = new_depth;
        Rc::make_mut(&mut node.items).extend(added);
        self.charge_work(copied + n_added)?;
        self.charge_nodes(copied + n_added)
    }

    fn run(&mut self) -> Result<Value, PickleError> {
        loop {
            self.at = self.pos;
            self.charge_work(1)?;
            let code = self.u8()?;
            match code {
                // PROTO n, FRAME n: nothing to build.
                op::PROTO => {
                    let v = self.u8()?;
                    if v > 5 {
                        return self.bad(format!("protocol {v} is newer than 5"));
                    }
                }
                op::FRAME => {
                    self.take(8)?;
                }
                op::STOP => {
                    let v = self.pop()?;
                    return Ok(v);
                }
                op::MARK => {
                    self.room_for_one_more()?;
                    self.stack.push(Slot::Mark)
                }
                op::POP => {
                    self.stack.pop().map(|_| ()).map_or_else(|| self.bad("POP on an empty stack"), Ok)?;
                }
                op::POP_MARK => {
                    self.pop_mark()?;
                }
                op::DUP => {
                    let v = self.top()?.clone();
                    self.push(v)?;
                }
                op::NONE => self.push(Value::None)?,
                op::NEWTRUE => self.push(Value::Bool(true))?,
                op::NEWFALSE => self.push(Value::Bool(false))?,
                op::BININT => {
                    let v = self.le(4)? as u32 as i32;
                    self.push(Value::Int(v as i64))?
                }
                op::BININT1 => {
                    let v = self.u8()?;
                    self.push(Value::Int(v as i64))?
                }
                op::BININT2 => {
                    let v = self.le(2)?;
                    self.push(Value::Int(v as i64))?
                }
                op::LONG1 => {
                    let n = self.u8()? as usize;
                    let b = self.take(n)?;
                    let v = self.long(b)?;
                    self.push(v)?
                }
                op::LONG4 => {
                    let n = self.le(4)? as usize;
                    let b = self.take(n)?;
                    let v = self.long(b)?;
                    self.push(v)?
                }
                op::INT | op::LONG => {
                    let line = self.line()?.trim_end_matches('L');
                    let v = match line {
                        "00" => Value::Bool(false),
                        "01" => Value::Bool(true),
                        s => match s.parse::<i64>() {
                            Ok(v) => Value::Int(v),
                            Err(_) => return self.bad(format!("{s:?} is not an integer")),
                        },
                    };
                    self.push(v)?
                }
                op::BINFLOAT => {
                    let v = f64::from_bits(u64::from_be_bytes(self.take(8)?.try_into().expect("8 bytes")));
                    self.push(Value::Float(v))?
                }
                op::FLOAT => {
                    let line = self.line()?;
                    let v = line.parse::<f64>().or_else(|_| self.bad(format!("{line:?} is not a float")))?;
                    self.push(Value::Float(v))?
                }
                op::BINUNICODE | op::BINUNICODE8 | op::SHORT_BINUNICODE => {
                    let n = match code {
                        op::BINUNICODE => self.le(4)?,
                        op::BINUNICODE8 => self.le(8)?,
                        _ => self.u8()? as u64,
                    };
                    let b = self.take(usize::try_from(n).unwrap_or(usize::MAX))?;
                    let v = self.string(b)?;
                    self.push(v)?
                }
                op::UNICODE => {
                    let line = self.line()?;
                    let v = self.string(line.as_bytes())?;
                    self.push(v)?
                }
                op::BINSTRING
                | op::SHORT_BINSTRING
                | op::BINBYTES
                | op::SHORT_BINBYTES
                | op::BINBYTES8
                | op::BYTEARRAY8 => {
                    let n = match code {
                        op::BINSTRING | op::BINBYTES => self.le(4)?,
                        op::SHORT_BINSTRING | op::SHORT_BINBYTES => self.u8()? as u64,
                        _ => self.le(8)?,
                    };
                    let b = self.take(usize::try_from(n).unwrap_or(usize::MAX))?;
                    // Python 2 str (T, U) as text when it is UTF-8, as bytes otherwise.
                    let v = match (code, std::str::from_utf8(b)) {
                        (op::BINSTRING | op::SHORT_BINSTRING, Ok(_)) => self.string(b)?,
                        _ => self.bytes_value(b)?,
                    };
                    self.push(v)?
                }
                op::STRING => {
                    let line = self.line()?;
                    let t = line.trim();
                    let inner = t
                        .strip_prefix('\'')
                        .and_then(|s| s.strip_suffix('\''))
                        .or_else(|| t.strip_prefix('"').and_then(|s| s.strip_suffix('"')));
                    let Some(inner) = inner else { return self.bad("STRING argument is not quoted") };
                    let v = self.string(inner.as_bytes())?;
                    self.push(v)?
                }
                op::EMPTY_TUPLE => {
                    let n = self.node(Vec::new())?;
                    self.push(Value::Tuple(n))?
                }
                op::EMPTY_LIST => {
                    let n = self.node(Vec::new())?;
                    self.push(Value::List(n))?
                }
                op::EMPTY_DICT => {
                    let n = self.node(Vec::new())?;
                    self.push(Value::Dict(n))?
                }
                op::EMPTY_SET => {
                    let n = self.node(Vec::new())?;
                    self.push(Value::Set(n))?
                }
                op::TUPLE | op::LIST | op::DICT | op::FROZENSET => {
                    let items = self.pop_mark()?;
                    self.charge_work(items.len() as u64)?;
                    if code == op::DICT && items.len() % 2 == 1 {
                        return self.bad("DICT with an odd number of items");
                    }
                    let n = self.node(items)?;
                    let v = match code {
                        op::TUPLE => Value::Tuple(n),
                        op::LIST => Value::List(n),
                        op::DICT => Value::Dict(n),
                        _ => Value::Set(n),
                    };
                    self.push(v)?
                }
                op::TUPLE1 | op::TUPLE2 | op::TUPLE3 => {
                    let k = (code - op::TUPLE1 + 1) as usize;
                    let mut items = Vec::with_capacity(k);
                    for _ in 0..k {
                        items.push(self.pop()?);
                    }
                    items.reverse();
                    let n = self.node(items)?;
                    self.push(Value::Tuple(n))?
                }
                op::APPEND => {
                    let v = self.pop()?;
                    self.extend_top(vec![v], "list")?
                }
                op::APPENDS => {
                    let items = self.pop_mark()?;
                    self.extend_top(items, "list")?
                }
                op::SETITEM => {
                    let v = self.pop()?;
                    let k = self.pop()?;
                    self.extend_top(vec![k, v], "dict")?
                }
                op::SETITEMS => {
                    let items = self.pop_mark()?;
                    if items.len() % 2 == 1 {
                        return self.bad("SETITEMS with an odd number of items");
                    }
                    self.extend_top(items, "dict")?
                }
                op::ADDITEMS => {
                    let items = self.pop_mark()?;
                    self.extend_top(items, "set")?
                }
                op::GLOBAL => {
                    let module = self.line()?;
                    let name = self.line()?;
                    self.charge_bytes((module.len() + name.len()) as u64)?;
                    self.push(Value::Global { module: module.into(), name: name.into() })?
                }
                op::STACK_GLOBAL => {
                    let name = self.pop()?;
                    let module = self.pop()?;
                    match (module, name) {
                        (Value::Str(module), Value::Str(name)) => self.push(Value::Global { module, name })?,
                        _ => return self.bad("STACK_GLOBAL needs two strings"),
                    }
                }
                op::REDUCE | op::BUILD => {
                    let arg = self.pop()?;
                    let callable = self.pop()?;
                    // `collections.OrderedDict()` is read as the empty dict it returns, so
                    // that SETITEMS can fill it (how torch pickles a state dict).
                    let empty_args = arg.as_seq().is_some_and(<[Value]>::is_empty);
                    if code == op::REDUCE && empty_args && callable.is_global("collections", "OrderedDict") {
                        let n = self.node(Vec::new())?;
                        self.push(Value::Dict(n))?;
                        continue;
                    }
                    let n = self.node(vec![callable, arg])?;
                    self.push(if code == op::REDUCE { Value::Reduce(n) } else { Value::Build(n) })?
                }
                op::NEWOBJ | op::NEWOBJ_EX => {
                    // NEWOBJ cls args / NEWOBJ_EX cls args kwargs: a call, like REDUCE.
                    let kwargs = if code == op::NEWOBJ_EX { Some(self.pop()?) } else { None };
                    let args = self.pop()?;
                    let cls = self.pop()?;
                    let mut items = vec![cls, args];
                    items.extend(kwargs);
                    let n = self.node(items)?;
                    self.push(Value::Reduce(n))?
                }
                op::BINPERSID => {
                    let pid = self.pop()?;
                    let n = self.node(vec![pid])?;
                    self.push(Value::PersistentId(n))?
                }
                op::PERSID => {
                    let line = self.line()?;
                    let s = self.string(line.as_bytes())?;
                    let n = self.node(vec![s])?;
                    self.push(Value::PersistentId(n))?
                }
                op::PUT | op::BINPUT | op::LONG_BINPUT | op::MEMOIZE => {
                    let key = match code {
                        op::PUT => {
                            let line = self.line()?;
                            line.parse::<u64>().or_else(|_| self.bad(format!("{line:?} is not a memo key")))?
                        }
                        op::BINPUT => self.u8()? as u64,
                        op::LONG_BINPUT => self.le(4)?,
                        _ => self.memo.len() as u64,
                    };
                    let v = self.top()?.clone();
                    self.room_for_one_more()?;
                    self.memo.insert(key, v);
                }
                op::GET | op::BINGET | op::LONG_BINGET => {
                    let key = match code {
                        op::GET => {
                            let line = self.line()?;
                            line.parse::<u64>().or_else(|_| self.bad(format!("{line:?} is not a memo key")))?
                        }
                        op::BINGET => self.u8()? as u64,
                        _ => self.le(4)?,
                    };
                    let Some(v) = self.memo.get(&key).cloned() else {
                        return self.bad(format!("memo key {key} was never stored"));
                    };
                    self.push(v)?
                }
                other => return self.bad(format!("opcode 0x{other:02x} is not supported")),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read_ok(b: &[u8]) -> Value {
        read(b, Limits::default()).unwrap()
    }

    #[test]
    fn scalars_and_containers_as_python_writes_them() {
        // pickle.dumps({'a': (1, -2, 3.5, None, True), 'b': [b'xy', 'é']}, protocol=2)
        let p = b"\x80\x02}q\x00(X\x01\x00\x00\x00aq\x01(K\x01J\xfe\xff\xff\xffG@\x0c\x00\x00\x00\x00\x00\x00N\x88tq\x02X\x01\x00\x00\x00bq\x03]q\x04(c_codecs\nencode\nq\x05X\x02\x00\x00\x00xyq\x06X\x06\x00\x00\x00latin1q\x07\x86q\x08Rq\tX\x02\x00\x00\x00\xc3\xa9q\neu.";
        let v = read_ok(p);
        let d: Vec<_> = v.as_dict().unwrap().collect();
        assert_eq!(d[0].0.as_str(), Some("a"));
        let t = d[0].1.as_seq().unwrap();
        assert_eq!(t[0], Value::Int(1));
        assert_eq!(t[1], Value::Int(-2));
        assert_eq!(t[2], Value::Float(3.5));
        assert_eq!(t[3], Value::None);
        assert_eq!(t[4], Value::Bool(true));
        let l = d[1].1.as_seq().unwrap();
        assert!(matches!(&l[0], Value::Reduce(n) if n.items[0].is_global("_codecs", "encode")));
        assert_eq!(l[1].as_str(), Some("é"));
        // dict > list > call > args tuple.
        assert_eq!(v.depth(), 4);
    }

    /// The opcodes the reader does not build (extension registry, instances by class name,
    /// out-of-band buffers) are refused by their byte, after a protocol 5 header.
    #[test]
    fn unsupported_opcodes_are_refused_by_byte() {
        for code in [op::EXT1, op::EXT2, op::EXT4, op::INST, op::OBJ, op::NEXT_BUFFER, op::READONLY_BUFFER] {
            let err = read(&[op::PROTO, 5, code, op::STOP], Limits::default()).unwrap_err().to_string();
            assert!(err.contains(&format!("opcode 0x{code:02x} is not supported")), "{err}");
        }
    }

    #[test]
    fn long1_is_twos_complement() {
        assert_eq!(read_ok(b"\x8a\x01\xff."), Value::Int(-1));
        assert_eq!(read_ok(b"\x8a\x02\x00\x01."), Value::Int(256));
        assert_eq!(read_ok(b"\x8a\x00."), Value::Int(0));
        assert!(matches!(read_ok(b"\x8a\x09\x00\x00\x00\x00\x00\x00\x00\x00\x01."), Value::BigInt(_)));
    }

    #[test]
    fn deep_nesting_is_refused_before_it_is_built() {
        // N, then 100,000 TUPLE1: a tuple nested 100,000 deep in 100 KB.
        let mut p = vec![b'N'];
        p.extend(std::iter::repeat_n(0x85u8, 100_000));
        p.push(b'.');
        let e = read(&p, Limits::default()).unwrap_err();
        assert_eq!(e, PickleError::Limit { at: 1 + 64, what: "levels of nesting", limit: 64 });
    }

    #[test]
    fn memo_fetches_share_and_copies_are_charged() {
        // A list of 1,000 Nones memoised, then fetched 100,000 times into one tuple: no
        // copy is made (the fetches are shared), so it fits; appending to a fetched, shared
        // list copies it each time and runs out of work.
        let mut p = vec![b']', b'('];
        p.extend(std::iter::repeat_n(b'N', 1000));
        p.extend([b'e', b'q', 0, b'(']);
        p.extend(std::iter::repeat_n([b'h', 0], 50_000).flatten());
        p.extend([b't', b'.']);
        let v = read_ok(&p);
        assert_eq!(v.as_seq().unwrap().len(), 50_000);
        let mut p = vec![b']', b'('];
        p.extend(std::iter::repeat_n(b'N', 1000));
        p.extend([b'e', b'q', 0]);
        p.extend(std::iter::repeat_n([b'h', 0, b'N', b'a', b'0'], 50_000).flatten());
        p.push(b'.');
        // Each append copies the 1,000 shared items: the copies run out of the node budget
        // after about 1,000 appends (of 50,000), long before memory or time matters.
        let e = read(&p, Limits::default()).unwrap_err();
        assert!(matches!(e, PickleError::Limit { what: "values", at, .. } if at < 1006 + 5 * 1100), "{e}");
    }

    #[test]
    fn malformed_streams_are_named() {
        for (p, want) in [
            (&b""[..], "ends inside"),
            (b"K", "ends inside"),
            (b"N", "ends inside"),
            (b"t.", "no MARK"),
            (b".", "empty"),
            (b"h\x05.", "never stored"),
            (b"Na.", "no value on top"),
            (b"NNa.", "expected a list on the stack, found None"),
            (b"\xff.", "not supported"),
            (b"\x80\x09.", "newer than 5"),
            (b"X\xff\xff\xff\xff.", "ends inside"),
        ] {
            let e = read(p, Limits::default()).unwrap_err().to_string();
            assert!(e.contains(want), "{p:?}: {e}");
        }
    }

    #[test]
    fn strings_and_values_are_counted() {
        let lim = Limits { max_bytes: 10, ..Limits::default() };
        let e = read(b"X\x0b\x00\x00\x00hello world.", lim).unwrap_err();
        assert!(matches!(e, PickleError::Limit { what: "bytes of strings", .. }));
        let lim = Limits { max_live: 3, ..Limits::default() };
        assert!(read(b"NNNN(((t.", lim).is_err());
    }
}
