//! `lrd shaders`: FLR's and the temporal stage's compute shaders in four
//! languages and the dispatch description for one frame size.

use crate::bench::parse_size;
use crate::methods::{self, FlrArgs};
use crate::runner::Inputs;
use std::path::Path;

/// `lrd shaders`: the shader modules in four languages plus `dispatch.md`, the
/// buffers, bindings, passes and parameter blocks for one frame size, of
/// FLR and of temporal FLR.
pub fn shaders(out: &Path, size: &str, f16_inputs: bool, flr: &FlrArgs) -> Result<(), String> {
    use lrdenoise::flr::gpu::{GpuLayouts, GpuPlan, InputFormat};
    let (w, h) = parse_size(size)?;
    // a frame with every guide, so the guide set is --guides (default normal,depth,ao)
    let probe = Inputs {
        w: 1,
        h: 1,
        noisy: vec![0.0; 3],
        normal: Some(vec![0.0; 3]),
        depth: Some(vec![0.0]),
        position: Some(vec![0.0; 3]),
        ao: Some(vec![0.0]),
        albedo: None,
        reference: None,
        motion: None,
        packed: None,
    };
    let cfg = flr.config(&probe)?;
    let plan = GpuPlan::new(cfg, w, h).map_err(|e| format!("shaders: {e}"))?;
    let s = lrdenoise_gpu::shaders().map_err(|e| e.to_string())?;
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let write = |name: &str, bytes: &[u8]| std::fs::write(out.join(name), bytes).map_err(|e| format!("{}: {e}", out.join(name).display()));
    write("flr.wgsl", s.wgsl.as_bytes())?;
    write("flr.spv", &le_bytes(&s.spirv))?;
    write("flr.metal", s.msl.as_bytes())?;
    write("flr.hlsl", s.hlsl.as_bytes())?;
    let input = if f16_inputs { InputFormat::F16 } else { InputFormat::F32 };
    let layouts = GpuLayouts::planar(w, h, input);
    let params = plan.params(&layouts).map_err(|e| e.to_string())?;
    let mut md = format!(
        "# FLR dispatch for {w}x{h}, {} ({} guide channels)\n\n\
         One bind group for every pass; binding i = the i-th buffer below. Inputs planar f32 \
         ({input:?} inputs, GpuLayouts::planar); other layouts: set the offsets and strides of the parameter block \
         (lrdenoise::flr::gpu::GpuPlan::params).\n\n| binding | buffer | access | bytes |\n|---:|---|---|---:|\n",
        methods::flag_line(&cfg),
        plan.guide_channels()
    );
    for b in plan.buffers(&layouts).map_err(|e| e.to_string())? {
        md += &format!("| {} | {:?} | {:?} | {} |\n", b.binding, b.buffer, b.access, b.bytes);
    }
    md += "\nPasses, in order (a storage barrier between consecutive passes):\n\n| entry point | workgroups |\n|---|---|\n";
    for p in plan.passes().iter() {
        md += &format!("| `{}` | {} x {} x {} |\n", p.name(), p.workgroups[0], p.workgroups[1], p.workgroups[2]);
    }
    md += &format!("\nThe parameter block (binding 0, {} bytes) for these layouts is `params.bin`.\n", lrdenoise::flr::gpu::PARAMS_BYTES);
    // temporal FLR: the stage's module around FLR's passes (FLR planned with its clamp off)
    let t = lrdenoise_gpu::translate(lrdenoise::temporal::gpu::TEMPORAL_WGSL).map_err(|e| e.to_string())?;
    write("temporal.wgsl", t.wgsl.as_bytes())?;
    write("temporal.spv", &le_bytes(&t.spirv))?;
    write("temporal.metal", t.msl.as_bytes())?;
    write("temporal.hlsl", t.hlsl.as_bytes())?;
    let temporal = flr.temporal_config()?;
    let tplan = lrdenoise::temporal::gpu::GpuTemporalPlan::new(temporal, cfg.guides, w, h).map_err(|e| format!("shaders: {e}"))?;
    // FLR inside temporal FLR: its clamp off (the stage clamps) and f32 planar inputs (the
    // stage writes the accumulated light into FLR's noisy buffer), whatever --f16-inputs says
    let tflr_cfg = lrdenoise::FlrConfig { fireflies: None, ..flr.temporal_window(cfg) };
    let tflr = GpuPlan::new(tflr_cfg, w, h).map_err(|e| format!("shaders: {e}"))?;
    let tlayouts = GpuLayouts::planar(w, h, InputFormat::F32);
    let tflr_params = tflr.params(&tlayouts).map_err(|e| e.to_string())?;
    let tparams = |frames| tplan.params(frames, cfg.fireflies, cfg.clamp_negative).map_err(|e| format!("shaders: {e}"));
    md += "\n## Temporal FLR\n\nThe temporal stage's module (`temporal.*`) has its own bind group; bindings Light, Guides and \
           Fitted are the noisy, guide and output buffers of FLR's bind group below: FLR planned with `fireflies: None` (the \
           stage clamps) and f32 planar inputs (the stage writes the accumulated light into the noisy buffer), whatever \
           the single-frame dispatch above uses; its parameter block is `temporal_flr_params.bin`. Each frame, upload \
           `temporal_params_first.bin` (a sequence's first frame) or `temporal_params.bin` (GpuTemporalPlan::params) and \
           the motion into Work at `GpuTemporalPlan::motion_offset`. The history is two buffers of one slot each: bind \
           the one `GpuTemporalPlan::slots` reads as HistoryIn and the other as HistoryOut (they swap each frame).\n\n\
           | binding | buffer | access | bytes |\n|---:|---|---|---:|\n";
    for b in tplan.buffers() {
        md += &format!("| {} | {:?} | {:?} | {} |\n", b.binding, b.buffer, b.access, b.bytes);
    }
    md += &format!("\nThe motion's two f32 planes go into Work at byte {}.\n", tplan.motion_offset());
    md += "\nFLR's bind group for temporal FLR:\n\n| binding | buffer | access | bytes |\n|---:|---|---|---:|\n";
    for b in tflr.buffers(&tlayouts).map_err(|e| e.to_string())? {
        md += &format!("| {} | {:?} | {:?} | {} |\n", b.binding, b.buffer, b.access, b.bytes);
    }
    md += "\nPasses, in order (a storage barrier between consecutive passes): the stage's, FLR's, then `t_resolve`.\n\n\
           | module | entry point | workgroups |\n|---|---|---|\n";
    let passes = tplan.passes_before().map(|p| ("temporal", p.name(), p.workgroups));
    let flr_passes = tflr.passes().iter().map(|p| ("flr", p.name(), p.workgroups)).collect::<Vec<_>>();
    let after = tplan.pass_after();
    for (module, name, g) in passes.into_iter().chain(flr_passes).chain([("temporal", after.name(), after.workgroups)]) {
        md += &format!("| {module} | `{name}` | {} x {} x {} |\n", g[0], g[1], g[2]);
    }
    write("temporal_flr_params.bin", tflr_params.as_bytes())?;
    write("temporal_params_first.bin", tparams(0)?.as_bytes())?;
    write("temporal_params.bin", tparams(1)?.as_bytes())?;
    write("dispatch.md", md.as_bytes())?;
    write("params.bin", params.as_bytes())?;
    println!("wrote flr.* and temporal.* (wgsl, spv, metal, hlsl), dispatch.md, params.bin and temporal*_params*.bin to {}", out.display());
    Ok(())
}

/// 32-bit words as little-endian bytes (SPIR-V files are little-endian words).
fn le_bytes(words: &[u32]) -> Vec<u8> {
    words.iter().flat_map(|w| w.to_le_bytes()).collect()
}
