//! The ONNX contract between the enhancer's writer (`campro train-enhancer`) and this
//! reader: node, input, output and metadata names, defined once for both.

/// Name of the enhancer's input (captured RGB in [0, 1]).
pub const INPUT: &str = "captured";
/// Name of the enhancer's output (enhanced RGB, about [0, 1]).
pub const OUTPUT: &str = "enhanced";
/// ONNX metadata key: height and width must be multiples of its value (a power of two).
pub const MULTIPLE_KEY: &str = "campro.multiple";

/// The restoration stage's output in a campro enhancer with a table.
pub const RESTORED: &str = "restored";
/// The U-Net's output before the face gate's blend.
pub const UNGATED: &str = "ungated";
/// The face gate's probability map (1, 1, H, W).
pub const GATE: &str = "gate";
/// Prefix of every node and initialiser of the restoration stage (`campro-train` writes
/// them, [`network_only`] strips them).
pub const RESTORE_PREFIX: &str = "restore.";
/// The restoration stage's table: (entries, 3) 8-bit output codes.
pub const RESTORE_TABLE: &str = "restore.table";
/// The restoration stage's bins: 768 floats, 256 per channel.
pub const RESTORE_BINS: &str = "restore.bins";
/// Prefix of the gate's pixelation nodes (the blocks the gate blends toward).
pub const GATE_PIX: &str = "gate.pix";
/// The gate blend's nodes, in order: `ungated · -1`, `toward + that`, `gate · that`;
/// the output is `ungated + gate.move`.
pub const GATE_BLEND: [&str; 3] = ["gate.neg", "gate.diff", "gate.move"];
