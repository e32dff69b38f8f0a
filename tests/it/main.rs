//! The product's integration tests, one binary (one linked test binary
//! instead of one per file: one link step, not one per file). Each module is one concern; shared fixtures
//! live in `dend-testkit`. The slow system tests (failover, crash safety, the
//! posing suite, process-memory measurements) are the `system` binary
//! (`tests/system/main.rs`).

mod admission;
mod asset_groups;
mod asset_normals;
mod broken_files;
mod cli;
mod cli_curvature;
mod cli_deform;
mod cli_gltf;
mod client_routes;
mod constraint_edits;
mod constraints_schema;
mod deform_props;
mod drag_loop;
mod elastic;
mod elastic_shapes;
mod factor_cache;
mod fuzz_replay;
mod generators;
mod gltf_assets;
mod libigl_oracle;
mod mesh_io;
mod morph_targets;
mod named_poses;
mod no_panic;
mod operators;
mod operators_invariance;
mod paper_reproduction;
mod path_independence;
mod rig_export;
mod server_e2e;
mod server_errors;
mod server_gltf;
mod server_json_errors;
mod server_leases;
mod server_limits;
mod server_openapi;
mod server_posing;
mod shared_meshes;
mod slow_store;
mod square_formulation;
mod takeover_reads;
mod ws_flow;
mod ws_frames;
