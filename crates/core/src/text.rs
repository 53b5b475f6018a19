//! Rows of numbers in text files (PMD, CSV exports): one line of `sep`-separated decimal
//! numbers parsed into `f32` readings, or nothing when the line is not exactly that.
//!
//! The readers keep their own parser for the refusal message (which token, which line); this
//! is their fast path for the lines that are well formed, which is nearly all of them.
//!
//! The inside of a JSON list of numbers (an MQTT frame's `values`) is read the same way:
//! [`parse_json_numbers`] reads exactly JSON's number grammar into `f64`, or nothing, and the
//! station's full JSON parse then says what is wrong.

/// Parse `line` (without its line end) as exactly `expected` numbers separated by `sep`,
/// each token trimmed of ASCII white space, into `out` (cleared first). Each number is read
/// as `f64` and then rounded to `f32`, as numpy reads a text number into `float32`, so the
/// readings are bit for bit those of the readers' slow path (an overflow gives ±infinity,
/// `nan`/`inf` are read as such). `false` (and `out` unspecified) when a token is empty or not
/// a decimal number, or the count differs.
pub fn parse_row(line: &str, sep: char, expected: usize, out: &mut Vec<f32>) -> bool {
    out.clear();
    out.reserve(expected);
    for token in line.trim_matches(is_blank).split(sep) {
        if out.len() == expected {
            return false;
        }
        match token.trim_matches(is_blank).parse::<f64>() {
            Ok(v) => out.push(v as f32),
            Err(_) => return false,
        }
    }
    out.len() == expected
}

fn is_blank(c: char) -> bool {
    c.is_ascii_whitespace()
}

/// Parse `text`, the inside of a JSON list (between `[` and `]`), as exactly `expected`
/// elements, each a JSON number (RFC 8259: `-?(0|[1-9][0-9]*)(.[0-9]+)?([eE][+-]?[0-9]+)?`)
/// or `null` (read as NaN), separated by commas with JSON white space (space, tab, CR, LF)
/// around them, into `out` (cleared first). A number is the nearest `f64` (as Python's
/// `float` of the text, and as an integer converted to a float: `-0` is 0). `false` (and
/// `out` unspecified) for anything else: another token, a number beyond the `f64` range, a
/// count other than `expected`.
pub fn parse_json_numbers(text: &[u8], expected: usize, out: &mut Vec<f64>) -> bool {
    out.clear();
    out.reserve(expected);
    let mut k = skip_space(text, 0);
    if k == text.len() {
        return expected == 0;
    }
    loop {
        if out.len() == expected {
            return false;
        }
        let Some((v, end)) = json_element(text, k) else {
            return false;
        };
        out.push(v);
        k = skip_space(text, end);
        match text.get(k) {
            None => return out.len() == expected,
            Some(b',') => k = skip_space(text, k + 1),
            Some(_) => return false,
        }
    }
}

fn skip_space(text: &[u8], mut k: usize) -> usize {
    while k < text.len() && matches!(text[k], b' ' | b'\t' | b'\r' | b'\n') {
        k += 1;
    }
    k
}

fn digits(text: &[u8], mut k: usize) -> usize {
    while k < text.len() && text[k].is_ascii_digit() {
        k += 1;
    }
    k
}

/// One element at `k`: its value and where it ends, or None when it is not a finite number
/// or `null`.
fn json_element(text: &[u8], k: usize) -> Option<(f64, usize)> {
    if text[k..].starts_with(b"null") {
        return Some((f64::NAN, k + 4));
    }
    let start = k;
    let mut k = k;
    if text.get(k) == Some(&b'-') {
        k += 1;
    }
    match text.get(k) {
        Some(b'0') => k += 1,
        Some(b'1'..=b'9') => k = digits(text, k + 1),
        _ => return None,
    }
    let integer = k;
    if text.get(k) == Some(&b'.') {
        let end = digits(text, k + 1);
        if end == k + 1 {
            return None;
        }
        k = end;
    }
    if matches!(text.get(k), Some(b'e' | b'E')) {
        k += 1;
        if matches!(text.get(k), Some(b'+' | b'-')) {
            k += 1;
        }
        let end = digits(text, k);
        if end == k {
            return None;
        }
        k = end;
    }
    let mut v = match exact_decimal(text, start, integer, k) {
        Some(v) => v,
        None => {
            // ASCII by construction; Rust's parse gives the nearest f64 (ties to even), as
            // Python does
            let token = std::str::from_utf8(&text[start..k]).ok()?;
            token.parse().ok()?
        }
    };
    if k == integer && v == 0.0 {
        v = 0.0; // an integer: -0 is the integer 0
    }
    v.is_finite().then_some((v, k))
}

/// What [`parse_json_frame`] read of a frame payload besides its values: `seq`, `t`, the
/// `unit` text (its byte range in the payload, when given) and `dt` (when given).
/// Powers of ten a double holds exactly.
const EXACT_TENS: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
];

/// The number token `text[start..end]` (checked JSON grammar; its integer part ends at
/// `integer`) when its digits make an integer of at most 2^53 and its power of ten is within
/// ±22: then both are doubles exactly and one multiplication or division, rounded once,
/// gives the nearest double (Clinger's fast path), the value a full parse gives. None
/// otherwise (the caller parses the token in full).
fn exact_decimal(text: &[u8], start: usize, integer: usize, end: usize) -> Option<f64> {
    let negative = text[start] == b'-';
    let mut k = start + usize::from(negative);
    let (mut m, mut count, mut scale) = (0u64, 0u32, 0i32);
    let mut take = |c: u8, m: &mut u64| -> Option<()> {
        if *m == 0 && c == b'0' {
            return Some(()); // a leading zero adds no digit
        }
        count += 1;
        if count > 16 {
            return None;
        }
        *m = *m * 10 + u64::from(c - b'0');
        Some(())
    };
    while k < integer {
        take(text[k], &mut m)?;
        k += 1;
    }
    if text.get(k) == Some(&b'.') {
        k += 1;
        while k < end && text[k].is_ascii_digit() {
            take(text[k], &mut m)?;
            scale -= 1;
            k += 1;
        }
    }
    if k < end {
        // the exponent: e, E, an optional sign, digits (at most a few of them here)
        k += 1;
        let minus = text[k] == b'-';
        k += usize::from(matches!(text[k], b'+' | b'-'));
        if end - k > 4 {
            return None;
        }
        let e: i32 = text[k..end]
            .iter()
            .fold(0, |e, &c| e * 10 + i32::from(c - b'0'));
        scale += if minus { -e } else { e };
    }
    if m > 1 << 53 || !(-22..=22).contains(&scale) {
        return None;
    }
    let magnitude = m as f64;
    let v = if scale < 0 {
        magnitude / EXACT_TENS[(-scale) as usize]
    } else {
        magnitude * EXACT_TENS[scale as usize]
    };
    Some(if negative { -v } else { v })
}

#[derive(Debug, Clone, PartialEq)]
pub struct PlainFrame {
    pub seq: u64,
    pub t: f64,
    pub unit: Option<(usize, usize)>,
    pub dt: Option<f64>,
}

/// A whole MQTT frame payload of the plain form, in one pass: one JSON object whose keys are
/// `seq` (an integer 0..2^63-1), `t` (a finite number), `values` (a list of exactly
/// `expected` numbers or `null`s, read as [`parse_json_numbers`] reads them, into `out`) and
/// optionally `unit` (a string of printable ASCII without escapes) and `dt` (a finite
/// number), each once, JSON white space around the tokens. None for anything else (another
/// key, a key twice, an escape, a number written as JSON does not, a non-ASCII byte, ...):
/// the station's JSON parse then reads it or says what is wrong, so whatever this reads is
/// what that parse reads (`t` and `dt` the nearest `f64`, as Python's `float` of the token).
pub fn parse_json_frame(text: &[u8], expected: usize, out: &mut Vec<f64>) -> Option<PlainFrame> {
    let mut k = skip_space(text, 0);
    if text.get(k) != Some(&b'{') {
        return None;
    }
    let (mut seq, mut t, mut unit, mut dt, mut values) = (None, None, None, None, false);
    k = skip_space(text, k + 1);
    loop {
        let (key, after) = plain_string(text, k)?;
        k = skip_space(text, after);
        if text.get(k) != Some(&b':') {
            return None;
        }
        k = skip_space(text, k + 1);
        k = match &text[key.0..key.1] {
            b"seq" if seq.is_none() => plain_integer(text, k).map(|(v, end)| {
                seq = Some(v);
                end
            })?,
            b"t" if t.is_none() => plain_number(text, k).map(|(v, end)| {
                t = Some(v);
                end
            })?,
            b"dt" if dt.is_none() => plain_number(text, k).map(|(v, end)| {
                dt = Some(v);
                end
            })?,
            b"unit" if unit.is_none() => plain_string(text, k).map(|(range, end)| {
                unit = Some(range);
                end
            })?,
            b"values" if !values => {
                if text.get(k) != Some(&b'[') {
                    return None;
                }
                let close = k + 1 + text[k + 1..].iter().position(|&c| c == b']')?;
                if !parse_json_numbers(&text[k + 1..close], expected, out) {
                    return None;
                }
                values = true;
                close + 1
            }
            _ => return None,
        };
        k = skip_space(text, k);
        match text.get(k) {
            Some(b',') => k = skip_space(text, k + 1),
            Some(b'}') => break,
            _ => return None,
        }
    }
    if skip_space(text, k + 1) != text.len() || !values {
        return None;
    }
    Some(PlainFrame {
        seq: seq?,
        t: t?,
        unit,
        dt,
    })
}

/// A string at `k` of printable ASCII without escapes: the byte range inside its quotes and
/// where it ends.
fn plain_string(text: &[u8], k: usize) -> Option<((usize, usize), usize)> {
    if text.get(k) != Some(&b'"') {
        return None;
    }
    let len = text[k + 1..].iter().position(|&c| c == b'"')?;
    let inner = &text[k + 1..k + 1 + len];
    if inner
        .iter()
        .any(|&c| !(b' '..=b'~').contains(&c) || c == b'\\')
    {
        return None;
    }
    Some(((k + 1, k + 1 + len), k + 2 + len))
}

/// A JSON integer at `k` in 0..2^63-1 (no sign, no fraction, no exponent), and where it ends.
fn plain_integer(text: &[u8], k: usize) -> Option<(u64, usize)> {
    let end = digits(text, k);
    if end == k || (text[k] == b'0' && end > k + 1) {
        return None;
    }
    if matches!(text.get(end), Some(b'.' | b'e' | b'E')) {
        return None; // a float to JSON's reader: not an integer seq
    }
    let mut v: u64 = 0;
    for &c in &text[k..end] {
        v = v.checked_mul(10)?.checked_add(u64::from(c - b'0'))?;
    }
    (v <= i64::MAX as u64).then_some((v, end))
}

/// A finite JSON number at `k` (not `null`), and where it ends.
fn plain_number(text: &[u8], k: usize) -> Option<(f64, usize)> {
    if text.get(k) == Some(&b'n') {
        return None;
    }
    json_element(text, k)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(line: &str, n: usize) -> Option<Vec<f32>> {
        let mut out = Vec::new();
        parse_row(line, '\t', n, &mut out).then_some(out)
    }

    #[test]
    fn reads_counts_and_decimals() {
        assert_eq!(
            row("0\t12\t3.5\t-2e1\n", 4),
            Some(vec![0.0, 12.0, 3.5, -20.0])
        );
        assert_eq!(row(" 1 \t 2\t3 ", 3), Some(vec![1.0, 2.0, 3.0]));
    }

    #[test]
    fn rounds_through_f64_like_numpy() {
        let got = row("0.1\t1e308\t-1e400\t1e-50", 4).unwrap();
        assert_eq!(got[0], 0.1f64 as f32);
        assert_eq!(got[1], f32::INFINITY);
        assert_eq!(got[2], f32::NEG_INFINITY);
        assert_eq!(got[3], 0.0);
        assert!(row("nan\t1", 2).unwrap()[0].is_nan());
    }

    fn numbers(text: &str, n: usize) -> Option<Vec<f64>> {
        let mut out = Vec::new();
        parse_json_numbers(text.as_bytes(), n, &mut out).then_some(out)
    }

    #[test]
    fn reads_json_numbers_and_nulls() {
        let got = numbers(" 0, -12 ,3.5e-1,\n2E+2,null ,0.1, -0, -0.0", 8).unwrap();
        assert_eq!(&got[..4], &[0.0, -12.0, 0.35, 200.0]);
        assert!(got[4].is_nan());
        assert_eq!(got[5], 0.1);
        assert!(got[6] == 0.0 && got[6].is_sign_positive());
        assert!(got[7] == 0.0 && got[7].is_sign_negative());
        assert_eq!(numbers("", 0), Some(vec![]));
        assert_eq!(numbers(" \n", 0), Some(vec![]));
        assert_eq!(
            numbers("123456789012345678901234567890", 1),
            Some(vec![1.2345678901234568e29])
        );
    }

    #[test]
    fn refuses_what_json_does_not_allow_or_is_not_finite() {
        for bad in [
            "1,,3",
            "1,2,",
            ",1,2",
            "01,2,3",
            "1.,2,3",
            ".5,2,3",
            "+1,2,3",
            "1e,2,3",
            "1,2,3,4",
            "1,2",
            "NaN,1,2",
            "Infinity,1,2",
            "1e400,1,2",
            "-1e400,1,2",
            "true,1,2",
            "1 2,3,4",
            "nul,1,2",
            "\"1\",2,3",
            "1,2,3 x",
            "0x1,2,3",
            "1\u{a0},2,3",
            "-,1,2",
            "1e+,2,3",
        ] {
            assert_eq!(numbers(bad, 3), None, "{bad:?}");
        }
        assert_eq!(numbers("1,2,3", 3), Some(vec![1.0, 2.0, 3.0]));
    }

    #[test]
    fn refuses_what_is_not_exactly_the_row() {
        for bad in [
            "1\t\t3",
            "1\tabc\t3",
            "1\t0x10\t3",
            "1\t2",
            "1\t2\t3\t4",
            "1 2\t3\t4",
            "",
        ] {
            assert_eq!(row(bad, 3), None, "{bad:?}");
        }
    }
}

#[cfg(test)]
mod frame_tests {
    use super::*;

    fn frame(text: &str, n: usize) -> Option<(PlainFrame, Vec<f64>)> {
        let mut out = Vec::new();
        parse_json_frame(text.as_bytes(), n, &mut out).map(|f| (f, out))
    }

    #[test]
    fn the_exact_decimals_are_the_full_parse() {
        let tokens = [
            "0.1",
            "-0.0",
            "-0",
            "0e0",
            "1E+2",
            "2.5e-3",
            "123.45678",
            "9007199254740992",
            "9007199254740993",
            "0.30000000000000004",
            "1e22",
            "1e23",
            "4.9e-324",
            "-1.5E-300",
            "8.000001",
            "00",
            "1234567890123456.7",
            "0.000001234567",
            "1e-22",
            "3.14159e10",
        ];
        for token in tokens {
            let mut out = Vec::new();
            if parse_json_numbers(token.as_bytes(), 1, &mut out) {
                let want: f64 = token.parse().unwrap();
                let want = if want == 0.0 && !token.contains(['.', 'e', 'E']) {
                    0.0
                } else {
                    want
                };
                assert_eq!(out[0].to_bits(), want.to_bits(), "{token}");
            }
        }
        let mut state = 0x2545_f491_4f6c_dd1du64;
        for _ in 0..100_000 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let digits = 1 + (state % 17) as usize;
            let point = (state >> 8) as usize % (digits + 1);
            let mut token = format!("{:017}", state >> 10)[..digits].to_string();
            token = token.trim_start_matches('0').to_string();
            if token.is_empty() {
                token.push('0');
            }
            if point < token.len() && point > 0 {
                token.insert(point, '.');
            }
            if state.is_multiple_of(3) {
                token = format!("{token}e{}", (state >> 40) as i64 % 30 - 15);
            }
            let mut out = Vec::new();
            assert!(parse_json_numbers(token.as_bytes(), 1, &mut out), "{token}");
            let want: f64 = token.parse().unwrap();
            assert_eq!(out[0].to_bits(), want.to_bits(), "{token}");
        }
    }

    #[test]
    fn reads_the_plain_payload_in_any_key_order() {
        let (f, v) = frame(
            r#"{"seq":7,"t":12.25,"values":[1,null,-0.5],"unit":"pF"}"#,
            3,
        )
        .unwrap();
        assert_eq!((f.seq, f.t, f.dt), (7, 12.25, None));
        let text = br#"{"seq":7,"t":12.25,"values":[1,null,-0.5],"unit":"pF"}"#;
        let (a, b) = f.unit.unwrap();
        assert_eq!(&text[a..b], b"pF");
        assert_eq!((v[0], v[2]), (1.0, -0.5));
        assert!(v[1].is_nan());
        let (g, _) = frame(
            " {\"values\" : [ 1 ,2 ] ,\n\"dt\":0.001, \"t\": 4, \"seq\": 0 } ",
            2,
        )
        .unwrap();
        assert_eq!((g.seq, g.t, g.dt, g.unit), (0, 4.0, Some(0.001), None));
        assert_eq!(
            frame(r#"{"seq":9223372036854775807,"t":-0,"values":[]}"#, 0)
                .unwrap()
                .0
                .t,
            0.0
        );
    }

    #[test]
    fn leaves_everything_else_to_the_full_parse() {
        for bad in [
            r#"{"seq":1,"t":1,"values":[1,2]}"#,           // another count
            r#"{"seq":1,"t":1,"values":[1,2,3],"x":1}"#,   // another key
            r#"{"seq":1,"seq":1,"t":1,"values":[1,2,3]}"#, // a key twice
            r#"{"seq":1,"t":1,"values":[1,2,3],"element_times":[0,1,2]}"#,
            r#"{"seq":-1,"t":1,"values":[1,2,3]}"#,
            r#"{"seq":1.0,"t":1,"values":[1,2,3]}"#,
            r#"{"seq":01,"t":1,"values":[1,2,3]}"#,
            r#"{"seq":9223372036854775808,"t":1,"values":[1,2,3]}"#,
            r#"{"seq":true,"t":1,"values":[1,2,3]}"#,
            r#"{"seq":1,"t":null,"values":[1,2,3]}"#,
            r#"{"seq":1,"t":1e999,"values":[1,2,3]}"#,
            r#"{"seq":1,"t":"1","values":[1,2,3]}"#,
            r#"{"seq":1,"values":[1,2,3]}"#,
            r#"{"seq":1,"t":1}"#,
            r#"{"seq":1,"t":1,"values":[[1],2,3]}"#,
            r#"{"seq":1,"t":1,"values":[1,2,3],"unit":"p\u0046"}"#,
            "{\"seq\":1,\"t\":1,\"values\":[1,2,3],\"unit\":\"\u{e9}\"}",
            r#"{"\u0073eq":1,"t":1,"values":[1,2,3]}"#,
            r#"{"seq":1,"t":1,"values":[1,2,3],}"#,
            r#"{"seq":1,"t":1,"values":[1,2,3]} x"#,
            r#"{"seq":1,"t":1,"values":[1,2,3]"#,
            "\u{feff}{\"seq\":1,\"t\":1,\"values\":[1,2,3]}",
            r#"[1,2,3]"#,
            "",
        ] {
            assert!(frame(bad, 3).is_none(), "{bad}");
        }
    }
}
