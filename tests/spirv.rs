//! What the kernel build guarantees of every kernel of every crate, read from the SPIR-V itself
//! (no device needed): no float operation a driver may fuse, and no float result whose precision
//! or order Vulkan leaves to the driver.

mod common;

use common::all_kernels;

/// Every float operation of every kernel is decorated `NoContraction` (softvk-build): no driver
/// may fuse `a * b + c` into one rounding, so each is the IEEE operation everywhere.
#[test]
fn no_kernel_lets_a_driver_fuse_float_operations() {
    // SPIR-V opcodes: OpDecorate, and the float arithmetic whose result id is word 2.
    const DECORATE: u32 = 71;
    const NO_CONTRACTION: u32 = 42;
    const FLOAT_OPS: [u32; 14] = [
        127, // OpFNegate
        129, // OpFAdd
        131, // OpFSub
        133, // OpFMul
        136, // OpFDiv
        140, // OpFRem
        141, // OpFMod
        142, // OpVectorTimesScalar
        143, // OpMatrixTimesScalar
        144, // OpVectorTimesMatrix
        145, // OpMatrixTimesVector
        146, // OpMatrixTimesMatrix
        147, // OpOuterProduct
        148, // OpDot
    ];
    let mut checked = 0;
    for spec in all_kernels() {
        let words = spec.spirv;
        let (mut decorated, mut results) = (Vec::new(), Vec::new());
        let mut at = 5; // after the header
        while at < words.len() {
            let (count, op) = ((words[at] >> 16) as usize, words[at] & 0xFFFF);
            assert!(count > 0, "{}: malformed SPIR-V", spec.name);
            if op == DECORATE && words[at + 2] == NO_CONTRACTION {
                decorated.push(words[at + 1]);
            } else if FLOAT_OPS.contains(&op) {
                results.push(words[at + 2]);
            }
            at += count;
        }
        for id in &results {
            assert!(
                decorated.contains(id),
                "{}: float operation %{id} may be contracted",
                spec.name
            );
        }
        checked += results.len();
    }
    assert!(checked > 2_000, "only {checked} float operations seen");
}

/// The instructions of one SPIR-V module whose float result Vulkan leaves to the driver:
/// division, remainders, dot and matrix products (their order is unspecified), any
/// GLSL.std.450 instruction that is not exact, and the subgroup and group float sums and
/// products (a `subgroupAdd` of floats sums in an order each device picks). Their minimum
/// and maximum are exact, as GLSL.std.450's `FMin` and `FMax` below: the result is one of
/// the operands, whatever the order.
fn left_to_the_driver(words: &[u32]) -> Vec<&'static str> {
    const EXT_INST: u32 = 12;
    let core: [(u32, &str); 11] = [
        (136, "OpFDiv"),
        (140, "OpFRem"),
        (141, "OpFMod"),
        (144, "OpVectorTimesMatrix"),
        (145, "OpMatrixTimesVector"),
        (146, "OpMatrixTimesMatrix"),
        (148, "OpDot"),
        (265, "OpGroupFAdd"),
        (350, "OpGroupNonUniformFAdd"),
        (352, "OpGroupNonUniformFMul"),
        (5000, "OpGroupFAddNonUniformAMD"),
    ];
    // GLSL.std.450 instructions that are exact on every device (rounding to integers,
    // sign, min/max/clamp, step, bit conversions, integer operations).
    let exact: [u32; 27] = [
        2, 3, 4, 5, 6, 7, 8, 9, 10, 37, 38, 39, 40, 41, 42, 43, 44, 45, 47, 48, 73, 74, 75, 79, 80,
        81, 62,
    ];
    let mut found = Vec::new();
    let mut at = 5; // after the header
    while at < words.len() {
        let (count, op) = ((words[at] >> 16) as usize, words[at] & 0xFFFF);
        assert!(count > 0, "malformed SPIR-V");
        if let Some((_, name)) = core.iter().find(|(c, _)| *c == op) {
            found.push(*name);
        } else if op == EXT_INST && !exact.contains(&words[at + 4]) {
            found.push("a GLSL.std.450 instruction that is not exact");
        }
        at += count;
    }
    found.dedup();
    found
}

/// Every kernel's float results are fixed by IEEE: no instruction whose precision or
/// evaluation order Vulkan leaves to the driver (division, `exp`, `log`, `sqrt`, `sin`, `dot`,
/// matrix products, `mix`, `length`, subgroup float sums, ...). softvk's own maths
/// (`fmath.glsl`) replaces them.
#[test]
fn no_kernel_leaves_a_float_result_to_the_driver() {
    let found: Vec<String> = all_kernels()
        .flat_map(|spec| {
            left_to_the_driver(spec.spirv)
                .into_iter()
                .map(|what| format!("{} {what}", spec.name))
        })
        .collect();
    assert!(
        found.is_empty(),
        "left to the driver:\n{}",
        found.join("\n")
    );
}

/// The scan above sees the subgroup float arithmetic: a module holding nothing but
/// `subgroupAdd` or `subgroupMul` of a float (or their inclusive and exclusive scans, or the
/// older group forms) is refused, and one holding the integer forms or a float
/// `subgroupMin` / `subgroupMax` (which the tiled kernels use) is not.
#[test]
fn the_scan_refuses_subgroup_float_arithmetic() {
    // A header, then one instruction: opcode, result type %1, result %2, scope %3,
    // group operation (0 reduce, 1 inclusive scan, 2 exclusive scan), value %4.
    let module = |op: u32, group_op: u32| {
        [
            0x0723_0203,
            0x0001_0000,
            0,
            5,
            0,
            6 << 16 | op,
            1,
            2,
            3,
            group_op,
            4,
        ]
    };
    for op in [350, 352] {
        for group_op in 0..3 {
            assert_eq!(
                left_to_the_driver(&module(op, group_op)).len(),
                1,
                "opcode {op}"
            );
        }
    }
    for op in [265, 5000] {
        assert_eq!(left_to_the_driver(&module(op, 0)).len(), 1, "opcode {op}");
    }
    for op in [349, 351, 353, 354, 355, 356, 357, 358, 267, 270] {
        assert!(left_to_the_driver(&module(op, 0)).is_empty(), "opcode {op}");
    }
}
