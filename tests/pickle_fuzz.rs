//! Fuzzing the bounded pickle reader with structured streams: random sequences of real
//! opcodes with plausible arguments (containers, memo traffic, deep nesting, huge
//! lengths). Every stream must end in a value or a named error, never a panic, a hang or
//! unbounded memory. Failing inputs proptest finds are kept in
//! `pickle_fuzz.proptest-regressions` and replayed first.

use campro::pickle::{read, Limits, PickleError, Value};
use proptest::prelude::*;

/// One opcode with its argument bytes.
fn op() -> impl Strategy<Value = Vec<u8>> {
    prop_oneof![
        Just(vec![b'N']),
        Just(vec![b'(']),
        Just(vec![b't']),
        Just(vec![b'l']),
        Just(vec![b'd']),
        Just(vec![b']']),
        Just(vec![b'}']),
        Just(vec![b')']),
        Just(vec![0x85]),
        Just(vec![0x86]),
        Just(vec![0x87]),
        Just(vec![b'a']),
        Just(vec![b'e']),
        Just(vec![b's']),
        Just(vec![b'u']),
        Just(vec![b'R']),
        Just(vec![b'b']),
        Just(vec![b'Q']),
        Just(vec![b'0']),
        Just(vec![b'1']),
        Just(vec![b'2']),
        Just(vec![0x93]),
        Just(vec![0x94]),
        any::<u8>().prop_map(|k| vec![b'K', k]),
        any::<u8>().prop_map(|k| vec![b'q', k % 4]),
        any::<u8>().prop_map(|k| vec![b'h', k % 4]),
        any::<u32>().prop_map(|n| {
            let mut v = vec![b'j'];
            v.extend((n % 8).to_le_bytes());
            v
        }),
        any::<u32>().prop_map(|n| {
            let mut v = vec![b'X'];
            v.extend(n.to_le_bytes());
            v
        }),
        (0u8..8).prop_map(|n| {
            let mut v = vec![b'X', n, 0, 0, 0];
            v.extend(std::iter::repeat_n(b'a', n as usize));
            v
        }),
        (0u8..12).prop_map(|n| {
            let mut v = vec![0x8a, n];
            v.extend(std::iter::repeat_n(0xffu8, n as usize));
            v
        }),
        Just(b"ctorch\nFloatStorage\n".to_vec()),
        Just(b"ccollections\nOrderedDict\n".to_vec()),
        any::<u64>().prop_map(|f| {
            let mut v = vec![b'G'];
            v.extend(f.to_be_bytes());
            v
        }),
        Just(vec![0x80, 2]),
        Just(vec![b'.']),
    ]
}

/// A stream: some opcodes, then a tail repeating one opcode many times (the cheap way
/// a hostile file makes depth or copies), then STOP.
fn stream() -> impl Strategy<Value = Vec<u8>> {
    (proptest::collection::vec(op(), 0..64), op(), 0usize..20_000, proptest::collection::vec(op(), 0..8)).prop_map(
        |(head, rep, n, tail)| {
            let mut b: Vec<u8> = head.concat();
            for _ in 0..n {
                b.extend(&rep);
            }
            b.extend(tail.concat());
            b.push(b'.');
            b
        },
    )
}

fn depth_ok(v: &Value, limit: u32) -> bool {
    v.depth() <= limit
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 400, ..ProptestConfig::default() })]

    #[test]
    fn structured_streams_end_in_a_value_or_a_named_error(bytes in stream()) {
        let lim = Limits::default();
        match read(&bytes, lim) {
            Ok(v) => prop_assert!(depth_ok(&v, lim.max_depth)),
            Err(PickleError::Malformed { at, .. } | PickleError::Limit { at, .. }) => prop_assert!(at <= bytes.len()),
            Err(e) => prop_assert!(false, "unexpected error kind {e:?}"),
        }
    }

    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..4096)) {
        let _ = read(&bytes, Limits::default());
    }
}

/// The cost of the worst stream of each kind is bounded by the limits, not by the file:
/// a 1 MB stream of memo fetches of a 1,000-item container, of DUPs, and of nesting.
#[test]
fn hostile_streams_of_each_kind_stop_at_a_limit() {
    let big_list = {
        let mut p = vec![b']', b'('];
        p.extend(std::iter::repeat_n(b'N', 1000));
        p.extend([b'e', b'q', 0]);
        p
    };
    // Fetch and append: each append copies the shared list.
    let mut copies = big_list.clone();
    copies.extend(std::iter::repeat_n([b'h', 0, b'N', b'a', b'0'], 200_000).flatten());
    copies.push(b'.');
    // DUP then append: the same.
    let mut dups = big_list.clone();
    dups.extend(std::iter::repeat_n([b'2', b'N', b'a', b'0'], 250_000).flatten());
    dups.push(b'.');
    // A MARK flood.
    let marks: Vec<u8> = std::iter::repeat_n(b'(', 1_000_000).chain([b'.']).collect();
    // Nesting: a list appended into a new list 300,000 times.
    let mut nest = vec![b']'];
    nest.extend(std::iter::repeat_n([0x85], 300_000).flatten());
    nest.push(b'.');
    for (name, p) in [("copies", copies), ("dups", dups), ("marks", marks), ("nest", nest)] {
        let e = read(&p, Limits::default()).expect_err(name);
        assert!(matches!(e, PickleError::Limit { .. }), "{name}: {e}");
    }
}
