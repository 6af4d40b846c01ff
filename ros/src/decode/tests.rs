use super::*;
use crate::msgdef::Dialect;

const HEADER2: &str = "std_msgs/Header header\nuint8 small\nfloat64[2] pair\nstring[] names\nuint8[] data\n================================================================================\nMSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n================================================================================\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n";

/// CDR little-endian bytes of HEADER2's message, aligned by hand from the spec (offsets after
/// the 4-byte encapsulation header).
fn cdr_sample() -> Vec<u8> {
    let mut b = vec![0x00, 0x01, 0x00, 0x00]; // CDR_LE
    b.extend(7i32.to_le_bytes()); // stamp.sec @0
    b.extend(250u32.to_le_bytes()); // stamp.nanosec @4
    b.extend(4u32.to_le_bytes()); // frame_id length incl. NUL @8
    b.extend(b"cam\0"); // @12
    b.push(9); // small @16
    b.extend([0; 7]); // pad to 24
    b.extend(1.5f64.to_le_bytes()); // pair[0] @24
    b.extend((-2.0f64).to_le_bytes()); // pair[1] @32
    b.extend(2u32.to_le_bytes()); // names count @40
    b.extend(2u32.to_le_bytes()); // "a\0" @44
    b.extend(b"a\0");
    b.extend([0; 2]); // pad to 52
    b.extend(3u32.to_le_bytes()); // "bc\0" @52
    b.extend(b"bc\0"); // @56..59
    b.push(0); // pad to 60
    b.extend(3u32.to_le_bytes()); // data count @60
    b.extend([1, 2, 3]);
    b
}

#[test]
fn cdr_alignment_strings_and_byte_arrays() {
    let reg = Registry::parse("x/msg/T", HEADER2, Dialect::Ros2).unwrap();
    let m = decode(&reg, Encoding::Cdr, &cdr_sample()).unwrap();
    let Some(Value::Message(h)) = m.get("header") else { panic!("{m:?}") };
    let Some(Value::Message(stamp)) = h.get("stamp") else { panic!() };
    assert_eq!(stamp.get("sec"), Some(&Value::Int(7)));
    assert_eq!(stamp.get("nanosec"), Some(&Value::UInt(250)));
    assert_eq!(h.get("frame_id"), Some(&Value::String("cam".into())));
    assert_eq!(m.get("small"), Some(&Value::UInt(9)));
    assert_eq!(m.get("pair"), Some(&Value::Array(vec![Value::Float(1.5), Value::Float(-2.0)])));
    assert_eq!(m.get("names"), Some(&Value::Array(vec![Value::String("a".into()), Value::String("bc".into())])));
    assert_eq!(m.get("data"), Some(&Value::Bytes(vec![1, 2, 3])));
}

#[test]
fn cdr_big_endian() {
    let reg = Registry::parse("x/T", "uint16 a\nfloat64 b\n", Dialect::Ros2).unwrap();
    let mut b = vec![0x00, 0x00, 0x00, 0x00];
    b.extend(0x0102u16.to_be_bytes());
    b.extend([0; 6]);
    b.extend(0.25f64.to_be_bytes());
    let m = decode(&reg, Encoding::Cdr, &b).unwrap();
    assert_eq!(m.get("a"), Some(&Value::UInt(0x0102)));
    assert_eq!(m.get("b"), Some(&Value::Float(0.25)));
}

#[test]
fn ros1_is_packed_with_time_primitives() {
    let text =
        "Header header\nuint8 small\nfloat64 x\n===\nMSG: std_msgs/Header\nuint32 seq\ntime stamp\nstring frame_id\n";
    let reg = Registry::parse("x/T", text, Dialect::Ros1).unwrap();
    let mut b = Vec::new();
    b.extend(3u32.to_le_bytes());
    b.extend(10u32.to_le_bytes());
    b.extend(20u32.to_le_bytes());
    b.extend(2u32.to_le_bytes());
    b.extend(b"id");
    b.push(5);
    b.extend(0.5f64.to_le_bytes()); // no padding before it
    let m = decode(&reg, Encoding::Ros1, &b).unwrap();
    let Some(Value::Message(h)) = m.get("header") else { panic!() };
    assert_eq!(h.get("stamp"), Some(&Value::Time { sec: 10, nsec: 20 }));
    assert_eq!(m.get("x"), Some(&Value::Float(0.5)));
}

#[test]
fn corrupt_lengths_and_truncation_are_errors_naming_the_field() {
    let reg = Registry::parse("x/msg/T", HEADER2, Dialect::Ros2).unwrap();
    let good = cdr_sample();
    for cut in 0..good.len() {
        let e = decode(&reg, Encoding::Cdr, &good[..cut]).unwrap_err();
        assert!(e.offset <= cut, "{e}");
    }
    let mut huge = good.clone();
    huge[64..68].copy_from_slice(&u32::MAX.to_le_bytes());
    let e = decode(&reg, Encoding::Cdr, &huge).unwrap_err();
    assert_eq!((e.field.as_str(), e.offset), ("data", 68), "{e}");
    let mut no_nul = good;
    no_nul[19] = b'x';
    let e = decode(&reg, Encoding::Cdr, &no_nul).unwrap_err();
    assert_eq!(e.field, "header.frame_id", "{e}");
}
