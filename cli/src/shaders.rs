//! `lrd shaders`: FLR's compute shaders in four languages and the dispatch
//! description for one frame size.

use crate::bench::parse_size;
use crate::methods::{self, FlrArgs};
use crate::runner::Inputs;
use std::path::Path;

/// `lrd shaders`: the shader module in four languages plus `dispatch.md`, the
/// buffers, bindings, passes and parameter block for one frame size.
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
    write("dispatch.md", md.as_bytes())?;
    write("params.bin", params.as_bytes())?;
    println!("wrote flr.wgsl, flr.spv, flr.metal, flr.hlsl, dispatch.md and params.bin to {}", out.display());
    Ok(())
}

/// 32-bit words as little-endian bytes (SPIR-V files are little-endian words).
fn le_bytes(words: &[u32]) -> Vec<u8> {
    words.iter().flat_map(|w| w.to_le_bytes()).collect()
}
