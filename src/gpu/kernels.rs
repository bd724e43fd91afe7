//! The WGSL kernels and their pipelines. A kernel's source is the prelude (`common.wgsl`), the
//! files of one traversal and one entry-point file, concatenated: WGSL has no includes, and
//! concatenation keeps every shared function in one place without a preprocessor. Pipelines
//! are compiled on first use and kept for the life of the context (one set per device);
//! shader and pipeline creation run inside a validation error scope, so a bad shader is an
//! error status, never a panic.

use crate::cpu::traverse::Traversal;
use crate::error::{Error, Result, Rt2Status};

const COMMON: &str = include_str!("../../shaders/common.wgsl");
const STANDARD: &str = include_str!("../../shaders/standard.wgsl");
const RESTART: &str = include_str!("../../shaders/restart.wgsl");
const KD_RESTART: &str = include_str!("../../shaders/kd_restart.wgsl");
const PUSH_DOWN: &str = include_str!("../../shaders/push_down.wgsl");
const SHORT_STACK: &str = include_str!("../../shaders/short_stack.wgsl");
const PUSH_DOWN_SHORT_STACK: &str = include_str!("../../shaders/push_down_short_stack.wgsl");
const ROPES_WALK: &str = include_str!("../../shaders/ropes_walk.wgsl");
const ROPES: &str = include_str!("../../shaders/ropes.wgsl");
const ROPES_PP: &str = include_str!("../../shaders/ropes_pp.wgsl");
const QUERY: &str = include_str!("../../shaders/query.wgsl");
const SHADE: &str = include_str!("../../shaders/shade.wgsl");
const RENDER: &str = include_str!("../../shaders/render.wgsl");
pub(crate) const SCAN: &str = include_str!("../../shaders/scan.wgsl");

/// Which entry-point file a traversal is combined with.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Program {
    /// `intersect_main`, `occluded_main`.
    Query,
    /// `megakernel` and the `wave_*` kernels.
    Render,
}

/// The traversal's own files, after the prelude.
fn traversal_files(t: Traversal) -> &'static [&'static str] {
    match t {
        Traversal::Standard => &[STANDARD],
        Traversal::KdRestart => &[RESTART, KD_RESTART],
        Traversal::PushDown => &[RESTART, PUSH_DOWN],
        Traversal::ShortStack => &[RESTART, SHORT_STACK],
        Traversal::PushDownShortStack => &[RESTART, PUSH_DOWN_SHORT_STACK],
        Traversal::Ropes => &[ROPES_WALK, ROPES],
        Traversal::RopesPlusPlus => &[ROPES_WALK, ROPES_PP],
    }
}

/// Full WGSL source of one traversal's query or render module. Its first line says whether the
/// traversal starts secondary rays in the leaf of their origin (`start_leaf` in common.wgsl),
/// from the one place the CPU asks too.
pub fn source(t: Traversal, p: Program) -> String {
    let mut s = format!(
        "const STARTS_IN_ORIGIN_LEAF: bool = {};\n",
        t.starts_in_origin_leaf()
    );
    s.push_str(COMMON);
    for f in traversal_files(t) {
        s.push('\n');
        s.push_str(f);
    }
    let tail: &[&str] = match p {
        Program::Query => &[QUERY],
        Program::Render => &[SHADE, RENDER],
    };
    for f in tail {
        s.push('\n');
        s.push_str(f);
    }
    s
}

/// A module that declares every struct of the layout tests.
#[cfg(test)]
pub(crate) fn prelude_for_layout_tests() -> String {
    source(Traversal::Standard, Program::Render)
}

/// Compiles `source` and one pipeline per entry point, inside a validation error scope.
pub fn create_pipelines(
    device: &wgpu::Device,
    label: &str,
    source: &str,
    layout: &wgpu::PipelineLayout,
    entries: &[&str],
) -> Result<Vec<wgpu::ComputePipeline>> {
    let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    let pipelines: Vec<_> = entries
        .iter()
        .map(|e| {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(e),
                layout: Some(layout),
                module: &module,
                entry_point: Some(e),
                compilation_options: Default::default(),
                cache: None,
            })
        })
        .collect();
    match pollster::block_on(scope.pop()) {
        None => Ok(pipelines),
        Some(e) => Err(Error::new(
            Rt2Status::Internal,
            format!("GPU kernel '{label}' failed to compile: {e}"),
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every module parses and validates with naga (the checks wgpu runs), without a device.
    #[test]
    fn every_kernel_validates() {
        use wgpu::naga;
        let mut sources: Vec<(String, String)> = vec![("scan".into(), SCAN.into())];
        for t in Traversal::ALL {
            for p in [Program::Query, Program::Render] {
                sources.push((format!("{} {p:?}", t.name()), source(t, p)));
            }
        }
        for (name, src) in sources {
            let module = naga::front::wgsl::parse_str(&src)
                .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(&src)));
            naga::valid::Validator::new(
                naga::valid::ValidationFlags::all(),
                naga::valid::Capabilities::default(),
            )
            .validate(&module)
            .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(&src)));
        }
    }

    /// A kernel that does not compile is an error status from `create_pipelines`, not a
    /// panic through wgpu's default error handler.
    #[test]
    fn a_bad_kernel_is_an_error_not_a_panic() {
        let Some(gpu) = super::super::device::open_for_tests() else {
            return;
        };
        let dev = &gpu.devices[0];
        let bad = source(Traversal::Standard, Program::Query).replace("fn intersect_main", "fn ;");
        let e = create_pipelines(
            &dev.device,
            "bad",
            &bad,
            &dev.layouts.query,
            &["intersect_main"],
        )
        .unwrap_err();
        assert_eq!(e.status, Rt2Status::Internal);
        assert!(e.message.contains("failed to compile"), "{}", e.message);
        // The device still works afterwards.
        assert!(dev.pipelines(Traversal::Standard, Program::Query).is_ok());
    }
}
