//! Bounded reads and in-place writes of glTF accessors.
//!
//! An accessor is located once ([`locate`]): its buffer view must exist, it
//! must not be sparse, its component type and element type must be among
//! those the caller accepts, and every element (offset + stride × index +
//! element size) must lie inside the view and the view inside its buffer.
//! Only then are elements read or written, so no read goes out of bounds and
//! no allocation is larger than the buffer.

use gltf::accessor::{DataType, Dimensions};

use super::error::GltfError;

/// Where an accessor's elements are, checked against the buffers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Located {
    /// The accessor's index in the document.
    pub accessor: usize,
    /// The buffer holding the elements.
    pub buffer: usize,
    /// Byte offset of element 0 in the buffer.
    pub start: usize,
    /// Bytes from one element to the next.
    pub stride: usize,
    /// Number of elements.
    pub count: usize,
    /// Component type.
    pub data_type: DataType,
}

fn component_size(t: DataType) -> usize {
    match t {
        DataType::I8 | DataType::U8 => 1,
        DataType::I16 | DataType::U16 => 2,
        DataType::U32 | DataType::F32 => 4,
    }
}

/// Locates `acc`'s elements, requiring `dims` and one of `types`.
pub(crate) fn locate(
    acc: &gltf::Accessor<'_>,
    buffers: &[Vec<u8>],
    dims: Dimensions,
    types: &[DataType],
    what: &str,
) -> Result<Located, GltfError> {
    let bad = |message: String| GltfError::Accessor {
        accessor: acc.index(),
        message: format!("{what}: {message}"),
    };
    if acc.sparse().is_some() {
        return Err(GltfError::Unsupported {
            what: format!("sparse accessor {} ({what})", acc.index()),
        });
    }
    if acc.dimensions() != dims || !types.contains(&acc.data_type()) {
        return Err(bad(format!(
            "is {:?} {:?}, expected {dims:?} of {types:?}",
            acc.dimensions(),
            acc.data_type()
        )));
    }
    let view = acc
        .view()
        .ok_or_else(|| bad("has no bufferView (all zeros), which cannot be deformed".into()))?;
    let elem = component_size(acc.data_type()) * dims.multiplicity();
    let stride = view.stride().unwrap_or(elem);
    if stride < elem {
        return Err(bad(format!(
            "byteStride {stride} is less than the element size {elem}"
        )));
    }
    let buffer = view.buffer().index();
    let buf_len = buffers.get(buffer).map_or(0, Vec::len);
    let view_end = view
        .offset()
        .checked_add(view.length())
        .filter(|&e| e <= buf_len)
        .ok_or_else(|| {
            bad(format!(
                "bufferView {} (offset {}, length {}) is outside buffer {buffer} ({buf_len} bytes)",
                view.index(),
                view.offset(),
                view.length()
            ))
        })?;
    let start = view.offset().checked_add(acc.offset());
    let count = acc.count();
    let end = match (start, count) {
        (Some(s), 0) => Some(s),
        (Some(s), n) => stride
            .checked_mul(n - 1)
            .and_then(|x| x.checked_add(elem))
            .and_then(|x| x.checked_add(s)),
        (None, _) => None,
    };
    match (start, end) {
        (Some(start), Some(end)) if end <= view_end => Ok(Located {
            accessor: acc.index(),
            buffer,
            start,
            stride,
            count,
            data_type: acc.data_type(),
        }),
        _ => Err(bad(format!(
            "{count} elements at offset {} with stride {stride} overrun bufferView {} ({} bytes)",
            acc.offset(),
            view.index(),
            view.length()
        ))),
    }
}

/// Checks that a copied-through accessor (UVs, colours, joints, …) lies
/// inside its buffer; sparse ones and ones without a view hold nothing to
/// check here.
pub(crate) fn check_bounds(acc: &gltf::Accessor<'_>, buffers: &[Vec<u8>]) -> Result<(), GltfError> {
    if acc.sparse().is_some() || acc.view().is_none() {
        return Ok(());
    }
    let dims = acc.dimensions();
    locate(acc, buffers, dims, &[acc.data_type()], "attribute").map(|_| ())
}

fn f32_at(b: &[u8], at: usize) -> f32 {
    f32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

/// Reads `N` `f32` components per element.
pub(crate) fn read_f32<const N: usize>(loc: &Located, buffers: &[Vec<u8>]) -> Vec<[f32; N]> {
    let b = &buffers[loc.buffer];
    (0..loc.count)
        .map(|i| {
            let at = loc.start + i * loc.stride;
            std::array::from_fn(|k| f32_at(b, at + 4 * k))
        })
        .collect()
}

/// Writes `N` `f32` components per element, in place.
pub(crate) fn write_f32<const N: usize>(
    loc: &Located,
    buffers: &mut [Vec<u8>],
    values: &[[f32; N]],
) {
    let b = &mut buffers[loc.buffer];
    for (i, v) in values.iter().enumerate().take(loc.count) {
        let at = loc.start + i * loc.stride;
        for (k, x) in v.iter().enumerate() {
            b[at + 4 * k..at + 4 * k + 4].copy_from_slice(&x.to_le_bytes());
        }
    }
}

/// Reads an index accessor (`u8`, `u16` or `u32` scalars).
pub(crate) fn read_indices(loc: &Located, buffers: &[Vec<u8>]) -> Vec<u32> {
    let b = &buffers[loc.buffer];
    (0..loc.count)
        .map(|i| {
            let at = loc.start + i * loc.stride;
            match loc.data_type {
                DataType::U8 => u32::from(b[at]),
                DataType::U16 => u32::from(u16::from_le_bytes([b[at], b[at + 1]])),
                _ => u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]]),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn component_sizes() {
        assert_eq!(component_size(DataType::U8), 1);
        assert_eq!(component_size(DataType::U16), 2);
        assert_eq!(component_size(DataType::F32), 4);
    }

    #[test]
    fn strided_read_write_round_trip() {
        let loc = Located {
            accessor: 0,
            buffer: 0,
            start: 4,
            stride: 16,
            count: 3,
            data_type: DataType::F32,
        };
        let mut buffers = vec![vec![0xAB; 4 + 16 * 3]];
        let v = [[1.0f32, -2.0, 3.5], [0.0, 1e-3, 7.0], [9.0, 8.0, -0.0]];
        write_f32(&loc, &mut buffers, &v);
        assert_eq!(read_f32::<3>(&loc, &buffers), v.to_vec());
        // the 4 bytes between elements are untouched
        assert_eq!(&buffers[0][16..20], &[0xAB; 4]);
        assert_eq!(&buffers[0][..4], &[0xAB; 4]);
    }
}
