//! NPY arrays read header first: the header's shape and dtype are parsed and checked (shape
//! expected by the caller, size against the input budget, data length against the file)
//! before any buffer for the data is allocated. Supported dtypes: float32, float64, uint8,
//! uint16, either byte order, C or Fortran order.

use crate::{budget, Error, Real, Result};
use std::io::Read;
use std::path::Path;

/// The largest header accepted (numpy writes a few hundred bytes).
const MAX_HEADER_BYTES: usize = 1 << 16;

/// An element type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Dtype {
    F32,
    F64,
    U8,
    U16,
}

impl Dtype {
    fn size(self) -> usize {
        match self {
            Dtype::F32 => 4,
            Dtype::F64 => 8,
            Dtype::U8 => 1,
            Dtype::U16 => 2,
        }
    }

    /// A name for messages.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Dtype::F32 => "float32",
            Dtype::F64 => "float64",
            Dtype::U8 => "uint8",
            Dtype::U16 => "uint16",
        }
    }

    /// Whether this is an integer type (scaled to [0, 1] when read as colour).
    pub(crate) fn is_integer(self) -> bool {
        matches!(self, Dtype::U8 | Dtype::U16)
    }
}

/// A parsed NPY header.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct Header {
    pub dtype: Dtype,
    pub big_endian: bool,
    pub fortran_order: bool,
    pub shape: Vec<u64>,
    /// Bytes from the start of the stream to the first data byte.
    pub data_offset: u64,
}

impl Header {
    /// Number of elements (saturating: a hostile shape cannot overflow).
    pub fn len(&self) -> u64 {
        self.shape.iter().fold(1u64, |a, &d| a.saturating_mul(d))
    }

    /// Bytes of data the header claims (saturating).
    pub fn data_bytes(&self) -> u64 {
        self.len().saturating_mul(self.dtype.size() as u64)
    }

    /// Fails unless the array fits the input budget (`what` names the file and key).
    pub fn check_budget(&self, what: &str) -> Result<()> {
        budget::check_array(what, &self.shape)
    }
}

/// Reads and parses the header at the start of `r`.
pub(crate) fn read_header<R: Read>(r: &mut R) -> std::result::Result<Header, String> {
    let mut magic = [0u8; 8];
    r.read_exact(&mut magic)
        .map_err(|_| "not an NPY array (file too short for the header)".to_string())?;
    if &magic[..6] != b"\x93NUMPY" {
        return Err("not an NPY array (bad magic bytes)".into());
    }
    let (len, prefix) = match magic[6] {
        1 => {
            let mut b = [0u8; 2];
            r.read_exact(&mut b)
                .map_err(|_| "truncated NPY header".to_string())?;
            (u16::from_le_bytes(b) as usize, 10)
        }
        2 | 3 => {
            let mut b = [0u8; 4];
            r.read_exact(&mut b)
                .map_err(|_| "truncated NPY header".to_string())?;
            (u32::from_le_bytes(b) as usize, 12)
        }
        v => return Err(format!("unsupported NPY format version {v}")),
    };
    if len > MAX_HEADER_BYTES {
        return Err(format!(
            "NPY header of {len} bytes is implausibly long (at most {MAX_HEADER_BYTES})"
        ));
    }
    let mut text = vec![0u8; len];
    r.read_exact(&mut text)
        .map_err(|_| "truncated NPY header".to_string())?;
    let text = String::from_utf8(text).map_err(|_| "NPY header is not text".to_string())?;
    let mut p = Parser {
        s: text.as_bytes(),
        i: 0,
    };
    let dict = p.dict()?;
    let get = |k: &str| dict.iter().find(|(key, _)| key == k).map(|(_, v)| v);
    let descr = match get("descr") {
        Some(Value::Str(s)) => s.clone(),
        Some(_) => return Err("structured dtypes are not supported".into()),
        None => return Err("NPY header has no 'descr'".into()),
    };
    let fortran_order = match get("fortran_order") {
        Some(Value::Bool(b)) => *b,
        _ => return Err("NPY header has no boolean 'fortran_order'".into()),
    };
    let shape = match get("shape") {
        Some(Value::Tuple(t)) => t.clone(),
        _ => return Err("NPY header has no 'shape' tuple".into()),
    };
    let (big_endian, code) = match descr.as_bytes().first() {
        Some(b'<') | Some(b'=') => (false, &descr[1..]),
        Some(b'|') => (false, &descr[1..]),
        Some(b'>') => (true, &descr[1..]),
        _ => (false, descr.as_str()),
    };
    let dtype = match code {
        "f4" => Dtype::F32,
        "f8" => Dtype::F64,
        "u1" => Dtype::U8,
        "u2" => Dtype::U16,
        _ => {
            return Err(format!(
                "unsupported dtype '{descr}' (use float32, float64, uint8 or uint16)"
            ))
        }
    };
    Ok(Header {
        dtype,
        big_endian,
        fortran_order,
        shape,
        data_offset: (prefix + len) as u64,
    })
}

/// A value of the header's Python literal.
#[derive(Debug)]
enum Value {
    Str(String),
    Bool(bool),
    Int(u64),
    Tuple(Vec<u64>),
}

/// A minimal parser for the header dict (`{'descr': '<f4', 'fortran_order': False,
/// 'shape': (2, 3), }`).
struct Parser<'a> {
    s: &'a [u8],
    i: usize,
}

impl Parser<'_> {
    fn ws(&mut self) {
        while self.i < self.s.len() && self.s[self.i].is_ascii_whitespace() {
            self.i += 1;
        }
    }

    fn eat(&mut self, c: u8) -> bool {
        self.ws();
        if self.s.get(self.i) == Some(&c) {
            self.i += 1;
            true
        } else {
            false
        }
    }

    fn dict(&mut self) -> std::result::Result<Vec<(String, Value)>, String> {
        let bad = || "malformed NPY header".to_string();
        if !self.eat(b'{') {
            return Err(bad());
        }
        let mut out = Vec::new();
        loop {
            if self.eat(b'}') {
                return Ok(out);
            }
            let key = match self.value()? {
                Value::Str(s) => s,
                _ => return Err(bad()),
            };
            if !self.eat(b':') {
                return Err(bad());
            }
            let v = self.value()?;
            out.push((key, v));
            if out.len() > 16 {
                return Err(bad());
            }
            if !self.eat(b',') {
                return if self.eat(b'}') { Ok(out) } else { Err(bad()) };
            }
        }
    }

    fn value(&mut self) -> std::result::Result<Value, String> {
        let bad = || "malformed NPY header".to_string();
        self.ws();
        let c = *self.s.get(self.i).ok_or_else(bad)?;
        match c {
            b'\'' | b'"' => {
                let start = self.i + 1;
                let end = self.s[start..]
                    .iter()
                    .position(|&b| b == c)
                    .ok_or_else(bad)?;
                self.i = start + end + 1;
                Ok(Value::Str(
                    String::from_utf8_lossy(&self.s[start..start + end]).into_owned(),
                ))
            }
            b'(' => {
                self.i += 1;
                let mut dims = Vec::new();
                loop {
                    if self.eat(b')') {
                        return Ok(Value::Tuple(dims));
                    }
                    match self.value()? {
                        Value::Int(v) => dims.push(v),
                        _ => return Err(bad()),
                    }
                    if dims.len() > 32 {
                        return Err("NPY shape has too many dimensions".into());
                    }
                    if !self.eat(b',') {
                        return if self.eat(b')') {
                            Ok(Value::Tuple(dims))
                        } else {
                            Err(bad())
                        };
                    }
                }
            }
            b'0'..=b'9' => {
                let start = self.i;
                while self.i < self.s.len() && self.s[self.i].is_ascii_digit() {
                    self.i += 1;
                }
                let text = std::str::from_utf8(&self.s[start..self.i]).map_err(|_| bad())?;
                let v = text
                    .parse::<u64>()
                    .map_err(|_| format!("NPY shape dimension {text} is too large"))?;
                // Python 2 long suffix.
                if self.s.get(self.i) == Some(&b'L') {
                    self.i += 1;
                }
                Ok(Value::Int(v))
            }
            _ if self.s[self.i..].starts_with(b"True") => {
                self.i += 4;
                Ok(Value::Bool(true))
            }
            _ if self.s[self.i..].starts_with(b"False") => {
                self.i += 5;
                Ok(Value::Bool(false))
            }
            _ => Err(bad()),
        }
    }
}

/// How integer data is converted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Integers {
    /// Scale uint8 by 1/255 and uint16 by 1/65535 (colour, maps).
    Scale,
    /// Reject integer arrays (alpha and disparity of a stack, gradients).
    Reject,
}

/// Checks the dtype policy; `what` names the array in the message.
pub(crate) fn check_dtype(h: &Header, integers: Integers, what: &str) -> Result<()> {
    if integers == Integers::Reject && h.dtype.is_integer() {
        return Err(Error::input(
            what,
            format!("is {}; expected float32 or float64", h.dtype.name()),
        ));
    }
    Ok(())
}

/// Reads the `h.len()` values following the header from `r`, converted to `T` (integers
/// scaled to [0, 1]), in C (row-major) order. The caller has checked the budget.
pub(crate) fn read_data<T: Real, R: Read>(
    r: &mut R,
    h: &Header,
) -> std::result::Result<Vec<T>, String> {
    let n = usize::try_from(h.len()).map_err(|_| "array too large".to_string())?;
    let mut out = read_values(r, h, n, 0)?;
    if h.fortran_order && h.shape.len() > 1 {
        out = fortran_to_c(&out, &h.shape);
    }
    Ok(out)
}

/// Reads the next `count` values (in file order) from `r`, `done` values having been read
/// before (for messages).
pub(crate) fn read_values<T: Real, R: Read>(
    r: &mut R,
    h: &Header,
    count: usize,
    done: usize,
) -> std::result::Result<Vec<T>, String> {
    let size = h.dtype.size();
    let mut out = Vec::with_capacity(count);
    let mut buf = vec![0u8; (1 << 14) * size];
    let mut left = count;
    while left > 0 {
        let take = left.min(1 << 14);
        let bytes = &mut buf[..take * size];
        r.read_exact(bytes).map_err(|_| {
            format!(
                "truncated: the header claims {} values of {} ({} bytes), the data ends after about {}",
                h.len(),
                h.dtype.name(),
                h.data_bytes(),
                (done + count - left) * size
            )
        })?;
        for c in bytes.chunks_exact(size) {
            let v = match (h.dtype, h.big_endian) {
                (Dtype::F32, false) => f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64,
                (Dtype::F32, true) => f32::from_be_bytes([c[0], c[1], c[2], c[3]]) as f64,
                (Dtype::F64, be) => {
                    let a = [c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]];
                    if be {
                        f64::from_be_bytes(a)
                    } else {
                        f64::from_le_bytes(a)
                    }
                }
                (Dtype::U8, _) => c[0] as f64 / 255.0,
                (Dtype::U16, false) => u16::from_le_bytes([c[0], c[1]]) as f64 / 65535.0,
                (Dtype::U16, true) => u16::from_be_bytes([c[0], c[1]]) as f64 / 65535.0,
            };
            out.push(T::c(v));
        }
        left -= take;
    }
    Ok(out)
}

/// Reorders column-major data into row-major order.
fn fortran_to_c<T: Copy>(data: &[T], shape: &[u64]) -> Vec<T> {
    let dims: Vec<usize> = shape.iter().map(|&d| d as usize).collect();
    // Fortran strides: the first axis varies fastest.
    let mut strides = vec![1usize; dims.len()];
    for k in 1..dims.len() {
        strides[k] = strides[k - 1] * dims[k - 1];
    }
    let mut idx = vec![0usize; dims.len()];
    let mut out = Vec::with_capacity(data.len());
    for _ in 0..data.len() {
        out.push(data[idx.iter().zip(&strides).map(|(i, s)| i * s).sum::<usize>()]);
        // Increment the C-order index (last axis fastest).
        for k in (0..dims.len()).rev() {
            idx[k] += 1;
            if idx[k] < dims[k] {
                break;
            }
            idx[k] = 0;
        }
    }
    out
}

/// Opens an NPY file and reads its header, checking the claimed data length against the
/// file's size. Errors name the file.
pub(crate) fn open_npy(path: &Path) -> Result<(std::io::BufReader<std::fs::File>, Header)> {
    let file = super::files::open(path)?;
    let file_len = file
        .metadata()
        .map_err(|e| Error::file(path, format!("cannot read: {e}")))?
        .len();
    let mut r = std::io::BufReader::new(file);
    let h = read_header(&mut r).map_err(|e| Error::file(path, e))?;
    if h.data_offset.saturating_add(h.data_bytes()) > file_len {
        // Budget first: a huge claimed shape is reported as too large, not as truncated.
        h.check_budget(&path.display().to_string())?;
        return Err(Error::file(
            path,
            format!(
                "truncated: the header claims shape {:?} of {} ({} bytes of data), the file holds {}",
                h.shape,
                h.dtype.name(),
                h.data_bytes(),
                file_len.saturating_sub(h.data_offset)
            ),
        ));
    }
    Ok((r, h))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header(text: &str) -> std::result::Result<Header, String> {
        let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
        bytes.extend_from_slice(&(text.len() as u16).to_le_bytes());
        bytes.extend_from_slice(text.as_bytes());
        read_header(&mut bytes.as_slice())
    }

    #[test]
    fn parses_numpy_headers_and_rejects_malformed_ones() {
        let text = "{'descr': '<f4', 'fortran_order': False, 'shape': (3, 4), }  \n";
        let h = header(text).unwrap();
        assert_eq!(
            (h.dtype, h.shape.clone(), h.data_offset),
            (Dtype::F32, vec![3, 4], 10 + text.len() as u64)
        );
        let h = header("{'descr': '>u2', 'fortran_order': True, 'shape': (5,)}").unwrap();
        assert!(h.big_endian && h.fortran_order && h.shape == vec![5]);
        assert_eq!(
            header("{'descr': '<f8', 'fortran_order': False, 'shape': ()}")
                .unwrap()
                .len(),
            1
        );
        for bad in [
            "",
            "{",
            "{'descr': '<c8', 'fortran_order': False, 'shape': (2,)}",
            "{'descr': '<f4', 'shape': (2,)}",
            "{'descr': '<f4', 'fortran_order': False, 'shape': (99999999999999999999999,)}",
            "{'descr': [('a', '<f4')], 'fortran_order': False, 'shape': (2,)}",
        ] {
            assert!(header(bad).is_err(), "{bad}");
        }
        let huge = header("{'descr': '<f4', 'fortran_order': False, 'shape': (4294967296, 4294967296, 4294967296)}").unwrap();
        assert_eq!(huge.len(), u64::MAX);
    }

    #[test]
    fn reads_what_ndarray_npy_writes_in_either_order_and_dtype() {
        use ndarray_npy::WriteNpyExt;
        let dir = tempfile::tempdir().unwrap();
        let a = ndarray::Array2::from_shape_fn((3, 5), |(y, x)| (10 * y + x) as f64);
        let want: Vec<f64> = a.iter().copied().collect();
        let path = dir.path().join("a.npy");
        let check = |path: &Path| {
            let (mut r, h) = open_npy(path).unwrap();
            assert_eq!(h.shape, vec![3, 5]);
            read_data::<f64, _>(&mut r, &h).unwrap()
        };
        a.write_npy(std::fs::File::create(&path).unwrap()).unwrap();
        assert_eq!(check(&path), want);
        // Column-major: the transpose of a (5, 3) array is (3, 5) in Fortran order.
        let f = a.t().as_standard_layout().into_owned().reversed_axes();
        assert!(!f.is_standard_layout() && f == a);
        f.write_npy(std::fs::File::create(&path).unwrap()).unwrap();
        assert_eq!(check(&path), want);
        a.mapv(|v| v as f32)
            .write_npy(std::fs::File::create(&path).unwrap())
            .unwrap();
        assert_eq!(check(&path), want);
        a.mapv(|v| (v * 1000.0) as u16)
            .write_npy(std::fs::File::create(&path).unwrap())
            .unwrap();
        let scaled: Vec<f64> = want.iter().map(|v| v * 1000.0 / 65535.0).collect();
        assert_eq!(check(&path), scaled);
    }

    #[test]
    fn fortran_order_is_transposed() {
        // 2x3 array [[0,1,2],[3,4,5]] stored column-major: 0,3,1,4,2,5.
        let f = [0, 3, 1, 4, 2, 5];
        assert_eq!(fortran_to_c(&f, &[2, 3]), vec![0, 1, 2, 3, 4, 5]);
    }
}
