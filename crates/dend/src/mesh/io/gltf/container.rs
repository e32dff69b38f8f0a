//! The glTF containers: the GLB binary envelope (12-byte header, a JSON chunk
//! and an optional BIN chunk) and the buffers a `.gltf` names by URI
//! (`data:` URIs with base64 payloads, or side-car files next to it).
//!
//! Every length read from a header or from the document is checked against
//! the bytes actually present before anything is sliced or allocated: a GLB
//! header or a `byteLength` declaring 1 GB in a tiny file is an error, not an
//! allocation.

use std::path::Path;

use base64::Engine as _;

use super::error::GltfError;

/// `glTF` little-endian.
const GLB_MAGIC: u32 = 0x4654_6C67;
/// `JSON` chunk type.
const CHUNK_JSON: u32 = 0x4E4F_534A;
/// `BIN\0` chunk type.
const CHUNK_BIN: u32 = 0x004E_4942;

/// The two chunks of a GLB file, borrowed from its bytes.
#[derive(Debug)]
pub(crate) struct Glb<'a> {
    /// The JSON chunk (trailing space padding included).
    pub json: &'a [u8],
    /// The BIN chunk, if present (trailing zero padding included).
    pub bin: Option<&'a [u8]>,
}

fn read_u32(bytes: &[u8], at: usize) -> Result<u32, GltfError> {
    bytes
        .get(at..at + 4)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .ok_or_else(|| GltfError::Glb {
            offset: at,
            message: format!(
                "truncated: needs 4 bytes at {at}, the input has {}",
                bytes.len()
            ),
        })
}

/// Whether `bytes` starts like a GLB file.
pub(crate) fn is_glb(bytes: &[u8]) -> bool {
    bytes.len() >= 4 && read_u32(bytes, 0).ok() == Some(GLB_MAGIC)
}

/// Splits a GLB file into its chunks, checking the header, the declared
/// length and each chunk's bounds.
pub(crate) fn split_glb(bytes: &[u8]) -> Result<Glb<'_>, GltfError> {
    let err = |offset: usize, message: String| GltfError::Glb { offset, message };
    if read_u32(bytes, 0)? != GLB_MAGIC {
        return Err(err(0, "not a GLB file (magic is not `glTF`)".into()));
    }
    let version = read_u32(bytes, 4)?;
    if version != 2 {
        return Err(err(
            4,
            format!("GLB version {version} (only 2 is supported)"),
        ));
    }
    let declared = read_u32(bytes, 8)? as usize;
    if declared > bytes.len() {
        return Err(err(
            8,
            format!(
                "header declares {declared} bytes, the input has {}",
                bytes.len()
            ),
        ));
    }
    if declared < 20 {
        return Err(err(
            8,
            format!(
                "header declares {declared} bytes, less than a GLB header and one chunk header"
            ),
        ));
    }
    let bytes = &bytes[..declared];
    let mut at = 12;
    let mut chunks: Vec<(u32, &[u8])> = Vec::new();
    while at < bytes.len() {
        let len = read_u32(bytes, at)? as usize;
        let kind = read_u32(bytes, at + 4)?;
        let start = at + 8;
        let end = start
            .checked_add(len)
            .filter(|&e| e <= bytes.len())
            .ok_or_else(|| {
                err(
                    at,
                    format!(
                        "chunk declares {len} bytes, only {} remain",
                        bytes.len().saturating_sub(start)
                    ),
                )
            })?;
        chunks.push((kind, &bytes[start..end]));
        at = end;
    }
    let json = match chunks.first() {
        Some(&(CHUNK_JSON, json)) => json,
        Some(&(kind, _)) => {
            return Err(err(
                16,
                format!("first chunk has type {kind:#010x}, not JSON"),
            ));
        }
        None => return Err(err(12, "no JSON chunk".into())),
    };
    let bin = match chunks.get(1) {
        Some(&(CHUNK_BIN, bin)) => Some(bin),
        _ => None,
    };
    Ok(Glb { json, bin })
}

/// Assembles a GLB file from a JSON document and one binary buffer, padding
/// the JSON chunk with spaces and the BIN chunk with zeros to 4 bytes.
pub(crate) fn assemble_glb(json: &[u8], bin: &[u8]) -> Vec<u8> {
    let pad = |n: usize| (4 - n % 4) % 4;
    let json_len = json.len() + pad(json.len());
    let bin_len = bin.len() + pad(bin.len());
    let total = 12 + 8 + json_len + if bin.is_empty() { 0 } else { 8 + bin_len };
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(&GLB_MAGIC.to_le_bytes());
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json_len as u32).to_le_bytes());
    out.extend_from_slice(&CHUNK_JSON.to_le_bytes());
    out.extend_from_slice(json);
    out.resize(out.len() + pad(json.len()), b' ');
    if !bin.is_empty() {
        out.extend_from_slice(&(bin_len as u32).to_le_bytes());
        out.extend_from_slice(&CHUNK_BIN.to_le_bytes());
        out.extend_from_slice(bin);
        out.resize(out.len() + pad(bin.len()), 0);
    }
    out
}

/// The base64 data URI of a buffer.
pub(crate) fn data_uri(bytes: &[u8]) -> String {
    format!(
        "data:application/octet-stream;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(bytes)
    )
}

/// Where a `.gltf` file's side-car buffers are looked for.
#[derive(Debug, Clone, Copy)]
pub enum Sidecars<'p> {
    /// Relative URIs are resolved against this folder (the `.gltf` file's).
    Folder(&'p Path),
    /// Side-car files are refused ([`GltfError::ExternalBuffer`]): bytes
    /// received over the network, or read without a folder.
    Refuse,
}

/// The bytes of buffer `index` with `uri` (None: the GLB BIN chunk), checked
/// to hold at least `declared` bytes; the result is cut to `declared`.
pub(crate) fn resolve_buffer(
    index: usize,
    uri: Option<&str>,
    declared: usize,
    bin: Option<&[u8]>,
    sidecars: Sidecars<'_>,
) -> Result<Vec<u8>, GltfError> {
    let bytes: Vec<u8> = match uri {
        None => bin.ok_or(GltfError::MissingBin { buffer: index })?.to_vec(),
        Some(uri) if uri.starts_with("data:") => {
            let (head, payload) = uri.split_once(',').unwrap_or((uri, ""));
            if !head.ends_with(";base64") {
                return Err(GltfError::BadDataUri {
                    buffer: index,
                    message: "not a base64 data URI".into(),
                });
            }
            // base64 decodes to at most 3/4 of its length: bounded by the input
            base64::engine::general_purpose::STANDARD
                .decode(payload.trim())
                .map_err(|e| GltfError::BadDataUri {
                    buffer: index,
                    message: e.to_string(),
                })?
        }
        Some(uri) => match sidecars {
            Sidecars::Refuse => {
                return Err(GltfError::ExternalBuffer {
                    buffer: index,
                    uri: uri.to_owned(),
                })
            }
            Sidecars::Folder(dir) => {
                let decoded = percent_decoded(uri);
                let rel = Path::new(&decoded);
                if rel.is_absolute() || uri.contains("://") {
                    return Err(GltfError::ExternalBuffer {
                        buffer: index,
                        uri: uri.to_owned(),
                    });
                }
                let path = dir.join(rel);
                std::fs::read(&path).map_err(|e| GltfError::BufferFile {
                    buffer: index,
                    path: path.display().to_string(),
                    message: e.to_string(),
                })?
            }
        },
    };
    if bytes.len() < declared {
        return Err(GltfError::BufferTooShort {
            buffer: index,
            declared,
            actual: bytes.len(),
        });
    }
    let mut bytes = bytes;
    bytes.truncate(declared);
    Ok(bytes)
}

/// A relative URI with its `%XX` escapes decoded (`my%20mesh.bin`); a
/// malformed escape is kept as written.
fn percent_decoded(uri: &str) -> String {
    let b = uri.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        let hex = |c: u8| (c as char).to_digit(16);
        match (
            b[i],
            b.get(i + 1).copied().and_then(hex),
            b.get(i + 2).copied().and_then(hex),
        ) {
            (b'%', Some(h), Some(l)) => {
                out.push((h * 16 + l) as u8);
                i += 3;
            }
            (c, ..) => {
                out.push(c);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uri_escapes_are_decoded() {
        assert_eq!(percent_decoded("my%20mesh.bin"), "my mesh.bin");
        assert_eq!(percent_decoded("a%2"), "a%2");
        assert_eq!(percent_decoded("%zz.bin"), "%zz.bin");
    }

    #[test]
    fn glb_round_trip_and_padding() {
        let glb = assemble_glb(b"{\"a\":1}", &[1, 2, 3, 4, 5]);
        assert_eq!(glb.len() % 4, 0);
        let g = split_glb(&glb).unwrap();
        assert_eq!(std::str::from_utf8(g.json).unwrap().trim_end(), "{\"a\":1}");
        assert_eq!(&g.bin.unwrap()[..5], &[1, 2, 3, 4, 5]);
    }

    #[test]
    fn every_truncation_is_an_error() {
        let glb = assemble_glb(b"{\"asset\":{}}", &[7; 12]);
        for n in 0..glb.len() {
            assert!(
                split_glb(&glb[..n]).is_err(),
                "prefix of {n} bytes accepted"
            );
        }
    }

    #[test]
    fn huge_declared_chunk_is_refused_without_allocating() {
        let mut glb = assemble_glb(b"{}  ", &[]);
        glb[12..16].copy_from_slice(&(1u32 << 30).to_le_bytes());
        let e = split_glb(&glb).unwrap_err();
        assert!(matches!(e, GltfError::Glb { offset: 12, .. }), "{e}");
    }

    #[test]
    fn declared_buffer_longer_than_its_data_is_refused() {
        let e = resolve_buffer(0, None, 1 << 30, Some(&[0; 8]), Sidecars::Refuse).unwrap_err();
        assert!(matches!(
            e,
            GltfError::BufferTooShort {
                declared: 1073741824,
                actual: 8,
                ..
            }
        ));
        let uri = data_uri(&[1, 2, 3]);
        assert_eq!(
            resolve_buffer(0, Some(&uri), 3, None, Sidecars::Refuse).unwrap(),
            vec![1, 2, 3]
        );
        let e = resolve_buffer(0, Some("x.bin"), 3, None, Sidecars::Refuse).unwrap_err();
        assert!(matches!(e, GltfError::ExternalBuffer { .. }));
    }
}
