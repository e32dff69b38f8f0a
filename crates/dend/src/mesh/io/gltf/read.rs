//! Reading a glTF document into a [`GltfAsset`]: the scene's triangle
//! primitives in world space, with what export needs to put a pose back.

use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::Mode;
use nalgebra::{Matrix4, Vector3, Vector4};

use super::accessor::{check_bounds, locate, read_f32, read_indices, Located};
use super::asset::{Block, Container, GltfAsset, PrimitivePart};
use super::container::{is_glb, resolve_buffer, split_glb, Sidecars};
use super::error::GltfError;
use crate::mesh::Point;

/// Extensions that change how geometry is stored: refused.
pub(crate) const REFUSED_EXTENSIONS: &[&str] = &[
    "KHR_draco_mesh_compression",
    "EXT_meshopt_compression",
    "KHR_mesh_quantization",
    "EXT_mesh_gpu_instancing",
];

fn matrix_of(node: &gltf::Node<'_>) -> Matrix4<f64> {
    let m = node.transform().matrix();
    Matrix4::from_fn(|r, c| f64::from(m[c][r]))
}

fn json_error(e: &serde_json::Error) -> GltfError {
    GltfError::Json {
        line: e.line(),
        column: e.column(),
        message: e.to_string(),
    }
}

/// The nodes to visit: the default scene's (or the first scene's) roots, or,
/// in a document without scenes, every node that is nobody's child.
fn roots(doc: &gltf::Document) -> Vec<gltf::Node<'_>> {
    if let Some(scene) = doc.default_scene().or_else(|| doc.scenes().next()) {
        return scene.nodes().collect();
    }
    let mut child = vec![false; doc.nodes().len()];
    for n in doc.nodes() {
        for c in n.children() {
            child[c.index()] = true;
        }
    }
    doc.nodes().filter(|n| !child[n.index()]).collect()
}

/// Parses `bytes` (GLB or glTF JSON) into an asset.
/// Every accessor a primitive names (attributes, indices, morph targets)
/// exists. gltf-json's validation indexes the accessor list with the
/// POSITION attribute's index before it checks that index, so a file with
/// a bad one would panic inside it: this check runs first.
fn check_accessor_references(root: &gltf::json::Root) -> Result<(), GltfError> {
    let n = root.accessors.len();
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            let targets = prim.targets.iter().flatten().flat_map(|t| {
                t.positions
                    .iter()
                    .chain(&t.normals)
                    .chain(&t.tangents)
                    .map(|i| i.value())
            });
            let refs = prim
                .attributes
                .values()
                .map(|i| i.value())
                .chain(prim.indices.iter().map(|i| i.value()))
                .chain(targets);
            for i in refs {
                if i >= n {
                    return Err(GltfError::Invalid {
                        message: format!(
                            "mesh {m}, primitive {p} names accessor {i}; the file has {n}"
                        ),
                    });
                }
            }
        }
    }
    Ok(())
}

pub(crate) fn parse(bytes: &[u8], sidecars: Sidecars<'_>) -> Result<GltfAsset, GltfError> {
    let (json_bytes, bin, container) = if is_glb(bytes) {
        let glb = split_glb(bytes)?;
        (glb.json, glb.bin, Container::Glb)
    } else {
        (bytes, None, Container::Json)
    };
    let json: serde_json::Value = serde_json::from_slice(json_bytes).map_err(|e| json_error(&e))?;
    let mut root: gltf::json::Root =
        serde_json::from_value(json.clone()).map_err(|e| json_error(&e))?;
    for ext in root.extensions_required.iter().chain(&root.extensions_used) {
        if REFUSED_EXTENSIONS.contains(&ext.as_str()) {
            return Err(GltfError::Unsupported {
                what: format!("extension {ext} (compressed or quantized geometry)"),
            });
        }
    }
    // other required extensions (materials, textures) do not touch the
    // geometry: they are passed through, so gltf's validation is not told
    root.extensions_required.clear();
    check_accessor_references(&root)?;
    let doc = gltf::Document::from_json(root).map_err(|e| GltfError::Invalid {
        message: e.to_string(),
    })?;
    let buffers = doc
        .buffers()
        .map(|b| {
            let uri = match b.source() {
                gltf::buffer::Source::Bin => None,
                gltf::buffer::Source::Uri(u) => Some(u),
            };
            resolve_buffer(b.index(), uri, b.length(), bin, sidecars)
        })
        .collect::<Result<Vec<_>, _>>()?;

    let mut asset = GltfAsset {
        json,
        buffers,
        container,
        blocks: Vec::new(),
        positions: Vec::new(),
        triangles: Vec::new(),
        normals: Vec::new(),
        tangents: Vec::new(),
        parts: Vec::new(),
        summary: Default::default(),
    };
    asset.summary.name = doc
        .default_scene()
        .or_else(|| doc.scenes().next())
        .and_then(|s| s.name().map(str::to_owned));
    let mut visited = vec![false; doc.nodes().len()];
    let mut stack: Vec<(gltf::Node<'_>, Matrix4<f64>)> = roots(&doc)
        .into_iter()
        .map(|n| (n, Matrix4::identity()))
        .collect();
    while let Some((node, parent)) = stack.pop() {
        if std::mem::replace(&mut visited[node.index()], true) {
            return Err(GltfError::Invalid {
                message: format!("node {} appears twice in the scene hierarchy", node.index()),
            });
        }
        let world = parent * matrix_of(&node);
        for c in node.children() {
            stack.push((c, world));
        }
        if let Some(mesh) = node.mesh() {
            // a skinned mesh ignores its node's transform (glTF 2.0 §3.7.3)
            let placed = if node.skin().is_some() {
                Matrix4::identity()
            } else {
                world
            };
            add_mesh(&mut asset, &node, &mesh, placed)?;
            asset.summary.skinned |= node.skin().is_some();
        }
    }
    asset.summary.skins = doc.skins().len();
    asset.summary.materials = doc.materials().len();
    asset.summary.textures = doc.textures().len();
    asset.summary.animations = doc.animations().len();
    if asset.triangles.is_empty() {
        return Err(GltfError::NoTriangles);
    }
    Ok(asset)
}

fn add_mesh(
    asset: &mut GltfAsset,
    node: &gltf::Node<'_>,
    mesh: &gltf::Mesh<'_>,
    world: Matrix4<f64>,
) -> Result<(), GltfError> {
    let inverse = world
        .try_inverse()
        .ok_or(GltfError::SingularTransform { node: node.index() })?;
    let flip = world.fixed_view::<3, 3>(0, 0).determinant() < 0.0;
    asset.summary.meshes += 1;
    if asset.summary.name.is_none() {
        asset.summary.name = mesh.name().map(str::to_owned);
    }
    for prim in mesh.primitives() {
        let at = format!("mesh {} primitive {}", mesh.index(), prim.index());
        if prim.mode() != Mode::Triangles {
            return Err(GltfError::Unsupported {
                what: format!("{at}: mode {:?} (only TRIANGLES)", prim.mode()),
            });
        }
        asset.summary.primitives += 1;
        asset.summary.morph_targets += prim.morph_targets().len();
        check_attributes(asset, &prim, &at)?;
        let pos = prim
            .get(&gltf::Semantic::Positions)
            .ok_or_else(|| GltfError::Invalid {
                message: format!("{at} has no POSITION"),
            })?;
        let pos = locate(
            &pos,
            &asset.buffers,
            Dimensions::Vec3,
            &[DataType::F32],
            "POSITION",
        )?;
        let normal = prim
            .get(&gltf::Semantic::Normals)
            .map(|a| {
                locate(
                    &a,
                    &asset.buffers,
                    Dimensions::Vec3,
                    &[DataType::F32],
                    "NORMAL",
                )
            })
            .transpose()?;
        let tangent = prim
            .get(&gltf::Semantic::Tangents)
            .map(|a| {
                locate(
                    &a,
                    &asset.buffers,
                    Dimensions::Vec4,
                    &[DataType::F32],
                    "TANGENT",
                )
            })
            .transpose()?;
        let block = block_for(asset, node.index(), pos, normal, tangent, world, inverse)?;
        let (first, count) = (asset.blocks[block].first, pos.count);
        let indices = primitive_indices(asset, mesh, &prim, &at, count)?;
        let start = asset.triangles.len();
        for t in indices.chunks_exact(3) {
            let g = |k: usize| (first + t[k] as usize) as u32;
            asset.triangles.push(if flip {
                [g(0), g(2), g(1)]
            } else {
                [g(0), g(1), g(2)]
            });
        }
        asset.parts.push(PrimitivePart {
            node: node.index(),
            node_name: node.name().map(str::to_owned),
            mesh: mesh.index(),
            mesh_name: mesh.name().map(str::to_owned),
            primitive: prim.index(),
            triangles: start..asset.triangles.len(),
        });
    }
    Ok(())
}

/// Checks a primitive's attribute accessors (in their buffers, one count)
/// and lists their names in the asset's summary.
fn check_attributes(
    asset: &mut GltfAsset,
    prim: &gltf::Primitive<'_>,
    at: &str,
) -> Result<(), GltfError> {
    for (semantic, acc) in prim.attributes() {
        check_bounds(&acc, &asset.buffers)?;
        let name = semantic.to_string();
        if !asset.summary.attributes.contains(&name) {
            asset.summary.attributes.push(name);
        }
    }
    // (after the bounds, so an accessor past its buffer says so)
    // the spec: every attribute accessor of a primitive has the same
    // count (the vertex count); the layout code relies on it
    let counts: Vec<usize> = prim.attributes().map(|(_, a)| a.count()).collect();
    if counts.windows(2).any(|w| w[0] != w[1]) {
        return Err(GltfError::Invalid {
            message: format!("{at}: its attributes have different counts {counts:?}"),
        });
    }
    Ok(())
}

/// A primitive's triangle corners, indices into its `count` vertices (its
/// index accessor, or `0..count` without one), checked.
fn primitive_indices(
    asset: &GltfAsset,
    mesh: &gltf::Mesh<'_>,
    prim: &gltf::Primitive<'_>,
    at: &str,
    count: usize,
) -> Result<Vec<u32>, GltfError> {
    let indices = match prim.indices() {
        Some(a) => {
            let loc = locate(
                &a,
                &asset.buffers,
                Dimensions::Scalar,
                &[DataType::U8, DataType::U16, DataType::U32],
                "indices",
            )?;
            read_indices(&loc, &asset.buffers)
        }
        None => (0..count as u32).collect(),
    };
    if indices.len() % 3 != 0 {
        return Err(GltfError::Invalid {
            message: format!("{at}: {} indices is not a multiple of 3", indices.len()),
        });
    }
    if let Some(&bad) = indices.iter().find(|&&i| i as usize >= count) {
        return Err(GltfError::IndexOutOfRange {
            mesh: mesh.index(),
            primitive: prim.index(),
            index: bad,
            vertices: count,
        });
    }
    Ok(indices)
}

/// The block of `(node, POSITION accessor)`, created on first use.
fn block_for(
    asset: &mut GltfAsset,
    node: usize,
    pos: Located,
    normal: Option<Located>,
    tangent: Option<Located>,
    world: Matrix4<f64>,
    inverse: Matrix4<f64>,
) -> Result<usize, GltfError> {
    let uses = |b: &Block, a: usize| {
        b.position.accessor == a
            || b.normal.is_some_and(|l| l.accessor == a)
            || b.tangent.is_some_and(|l| l.accessor == a)
    };
    if let Some(i) = asset
        .blocks
        .iter()
        .position(|b| b.node == node && b.position.accessor == pos.accessor)
    {
        let b = &asset.blocks[i];
        if b.normal != normal || b.tangent != tangent {
            return Err(GltfError::Unsupported {
                what: format!(
                    "POSITION accessor {} paired with different NORMAL/TANGENT accessors in node {node}",
                    pos.accessor
                ),
            });
        }
        return Ok(i);
    }
    for a in [Some(pos), normal, tangent].into_iter().flatten() {
        if let Some(b) = asset.blocks.iter().find(|b| uses(b, a.accessor)) {
            return Err(GltfError::Unsupported {
                what: format!(
                    "accessor {} is used by node {} and node {node} (instanced meshes, or \
                     vertex data shared between primitives with different positions): \
                     one pose cannot be written back to both",
                    a.accessor, b.node
                ),
            });
        }
    }
    let first = asset.positions.len();
    if first + pos.count > u32::MAX as usize - 1 {
        return Err(GltfError::Invalid {
            message: format!("more than {} vertices", u32::MAX - 1),
        });
    }
    let local = read_f32::<3>(&pos, &asset.buffers);
    let lin = world.fixed_view::<3, 3>(0, 0).into_owned();
    let normal_matrix = lin.try_inverse().map(|m| m.transpose()).unwrap_or(lin);
    for p in &local {
        let w = world * Vector4::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]), 1.0);
        asset.positions.push([w.x, w.y, w.z]);
    }
    match normal {
        Some(loc) => {
            for n in read_f32::<3>(&loc, &asset.buffers) {
                let v = normal_matrix * Vector3::new(n[0], n[1], n[2]).cast::<f64>();
                asset.normals.push(unit(v));
            }
        }
        None => asset.normals.extend(std::iter::repeat_n(None, pos.count)),
    }
    match tangent {
        Some(loc) => {
            for t in read_f32::<4>(&loc, &asset.buffers) {
                let v = lin * Vector3::new(t[0], t[1], t[2]).cast::<f64>();
                asset.tangents.push(unit(v));
            }
        }
        None => asset.tangents.extend(std::iter::repeat_n(None, pos.count)),
    }
    asset.blocks.push(Block {
        node,
        position: pos,
        normal,
        tangent,
        first,
        world,
        inverse,
        local,
    });
    Ok(asset.blocks.len() - 1)
}

/// `v / |v|`, or None for a zero or non-finite vector.
pub(crate) fn unit(v: Vector3<f64>) -> Option<Point> {
    let n = v.norm();
    (n > 0.0 && n.is_finite()).then(|| [v.x / n, v.y / n, v.z / n])
}
