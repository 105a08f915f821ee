//! .npy files (format 1.0, C order, little-endian): how the learned detector's dataset reaches
//! numpy, and how its tests hand inputs to the reference runtime.

/// An .npy file (format 1.0): magic, header dict padded to 64 bytes, then the C-order data.
pub fn npy(dtype: &str, shape: &[usize], data: &[u8]) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let shape = if dims.len() == 1 { format!("({},)", dims[0]) } else { format!("({})", dims.join(", ")) };
    let mut header = format!("{{'descr': '{dtype}', 'fortran_order': False, 'shape': {shape}, }}");
    // Magic (6) + version (2) + length (2) + header + newline: a multiple of 64.
    let pad = 64 - (10 + header.len() + 1) % 64;
    header.push_str(&" ".repeat(pad % 64));
    header.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend((header.len() as u16).to_le_bytes());
    out.extend(header.as_bytes());
    out.extend(data);
    out
}

/// The little-endian bytes of a slice of numbers.
pub fn le_bytes<T: Copy, const N: usize>(v: &[T], f: fn(T) -> [u8; N]) -> Vec<u8> {
    v.iter().flat_map(|&x| f(x)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_npy_header_is_padded_to_64_bytes() {
        let f = npy("<i2", &[2, 3], &[0; 12]);
        assert_eq!(&f[..8], b"\x93NUMPY\x01\x00");
        let len = usize::from(u16::from_le_bytes([f[8], f[9]]));
        assert_eq!((10 + len) % 64, 0);
        let header = std::str::from_utf8(&f[10..10 + len]).unwrap_or_default();
        assert!(header.contains("'shape': (2, 3)") && header.ends_with('\n'), "{header}");
        assert_eq!(f.len(), 10 + len + 12);
        assert!(std::str::from_utf8(&npy("<u2", &[5], &[0; 10])[10..]).unwrap_or_default().contains("(5,)"));
    }
}
