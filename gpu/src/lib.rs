//! # lrdenoise-gpu
//!
//! Runs FLR's WGSL compute shaders ([`lrdenoise::flr::gpu`]) on a `wgpu` device:
//! the dispatch description of [`GpuPlan`] executed as written, so this crate
//! is also the reference for engines that run the shaders with their own API.
//! [`shaders`] converts the module to SPIR-V, MSL and HLSL with naga.
//!
//! ```no_run
//! use lrdenoise::{FlrConfig, Frame, Guides, GuideSet, ImageView, ImageViewMut};
//! let (w, h) = (64, 48);
//! let noisy = vec![0.5f32; w * h * 3];
//! let normal = vec![0.0f32; w * h * 3];
//! let depth = vec![1.0f32; w * h];
//! let mut flr = lrdenoise_gpu::GpuFlr::new(FlrConfig::with_guides(GuideSet::NORMAL_DEPTH), w, h)?;
//! println!("running on {}", flr.adapter_name());
//! let guides = Guides {
//!     normal: Some(ImageView::interleaved(&normal, w, h, 3)?),
//!     depth: Some(ImageView::interleaved(&depth, w, h, 1)?),
//!     ..Default::default()
//! };
//! let frame = Frame::new(ImageView::interleaved(&noisy, w, h, 3)?, guides);
//! let mut out = vec![0f32; w * h * 3];
//! let report = flr.denoise(&frame, &mut ImageViewMut::interleaved(&mut out, w, h, 3)?)?;
//! # Ok::<(), lrdenoise_gpu::GpuError>(())
//! ```

use lrdenoise::flr::gpu::{GpuLayouts, GpuPlan, InputFormat, FLR_WGSL};
use lrdenoise::{Arg, Error, FlrConfig, Frame, ImageViewMut, Report};
use std::fmt;

mod compute;
mod temporal;
pub use temporal::GpuTemporalFlr;

pub use lrdenoise::flr::gpu;

/// What can go wrong on the GPU path.
#[derive(Debug)]
pub enum GpuError {
    /// A size, layout or configuration error (as on the CPU path).
    Config(Error),
    /// No adapter (GPU or software rasteriser) is available.
    NoAdapter(String),
    /// The device refused the request, or a validation or runtime error occurred.
    Device(String),
    /// A shader could not be translated (`shaders`).
    Shader(String),
    /// A buffer the frame size needs is larger than the device allows for
    /// one buffer or binding (`max_buffer_size`, `max_storage_buffer_binding_size`):
    /// a smaller frame, fewer guides, or a device with larger limits.
    TooLarge {
        /// Which buffer.
        buffer: String,
        /// Its size in bytes.
        bytes: u64,
        /// The device's limit in bytes.
        limit: u64,
    },
}

impl fmt::Display for GpuError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            GpuError::Config(e) => write!(f, "{e}"),
            GpuError::NoAdapter(why) => write!(f, "no GPU adapter: {why}"),
            GpuError::Device(why) => write!(f, "GPU device error: {why}"),
            GpuError::Shader(why) => write!(f, "shader translation failed: {why}"),
            GpuError::TooLarge { buffer, bytes, limit } => {
                write!(f, "{buffer} needs {bytes} bytes, above this device's limit of {limit} bytes for one buffer")
            }
        }
    }
}

impl std::error::Error for GpuError {}

impl From<Error> for GpuError {
    fn from(e: Error) -> Self {
        GpuError::Config(e)
    }
}

/// FLR for one frame size and configuration on a wgpu device. Buffers and
/// pipelines are created once and reused for every frame.
#[derive(Debug)]
pub struct GpuFlr {
    device: wgpu::Device,
    queue: wgpu::Queue,
    adapter: String,
    plan: GpuPlan,
    pipelines: Vec<(wgpu::ComputePipeline, [u32; 3])>,
    bind_group: wgpu::BindGroup,
    /// Binding order: params, noisy, guides, stats, cells, tmp, models, output.
    buffers: Vec<wgpu::Buffer>,
    readback: wgpu::Buffer,
    /// Sample format of the uploaded inputs.
    input: InputFormat,
    /// Parameter blocks: [fit guides = output guides (upsample 1 only), separate fit guides].
    params: [Option<lrdenoise::flr::gpu::GpuParams>; 2],
    /// Which of `params` the uniform buffer holds.
    current: Option<usize>,
    /// Timestamp queries (two per pass) and their resolve buffer, when the device has them.
    timer: Option<(wgpu::QuerySet, wgpu::Buffer)>,
    /// GPU milliseconds of each pass of the last `denoise`.
    pass_ms: Option<Vec<f64>>,
    /// Host staging of the planar inputs (reused); converted to f16 when `input` is.
    noisy: Vec<f32>,
    guides: Vec<f32>,
    half: Vec<half::f16>,
}

/// Most timestamps written per frame: the beginning and end of each pass.
const TIMESTAMPS: u32 = 2 * lrdenoise::flr::gpu::MAX_PASSES as u32;
/// Readback bytes after the timestamps for a caller's counters (the temporal stage's).
const EXTRA_BYTES: u64 = 16;

/// Requests the default adapter and a device with default limits, except
/// the largest buffer and storage binding, which are the adapter's own
/// (wgpu's defaults, 256 and 128 MiB, are below what 4K frames need, and
/// what many adapters allow).
pub fn default_device() -> Result<(wgpu::Device, wgpu::Queue, String), GpuError> {
    let instance = wgpu::Instance::default();
    let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions::default()))
        .map_err(|e| GpuError::NoAdapter(e.to_string()))?;
    let info = adapter.get_info();
    let name = format!("{} ({:?}, {:?})", info.name, info.device_type, info.backend);
    // timestamps where the adapter has them: per-pass GPU times (`GpuFlr::pass_times_ms`)
    let own = adapter.limits();
    let required_limits = wgpu::Limits {
        max_buffer_size: own.max_buffer_size,
        max_storage_buffer_binding_size: own.max_storage_buffer_binding_size,
        ..wgpu::Limits::default()
    };
    let desc = wgpu::DeviceDescriptor {
        required_features: adapter.features() & wgpu::Features::TIMESTAMP_QUERY,
        required_limits,
        ..Default::default()
    };
    let (device, queue) = pollster::block_on(adapter.request_device(&desc)).map_err(|e| GpuError::Device(e.to_string()))?;
    Ok((device, queue, name))
}

impl GpuFlr {
    /// Plans FLR and creates its pipelines and buffers on the default adapter
    /// (inputs uploaded as f32).
    pub fn new(cfg: FlrConfig, width: usize, height: usize) -> Result<Self, GpuError> {
        Self::with_input(cfg, width, height, InputFormat::F32)
    }

    /// As [`GpuFlr::new`], uploading the inputs in `input` format (f16: half the bytes).
    pub fn with_input(cfg: FlrConfig, width: usize, height: usize, input: InputFormat) -> Result<Self, GpuError> {
        let (device, queue, name) = default_device()?;
        Self::with_device(device, queue, name, cfg, width, height, input)
    }

    /// As [`GpuFlr::with_input`] on the caller's device (`adapter` is only a label).
    pub fn with_device(
        device: wgpu::Device,
        queue: wgpu::Queue,
        adapter: String,
        cfg: FlrConfig,
        width: usize,
        height: usize,
        input: InputFormat,
    ) -> Result<Self, GpuError> {
        let plan = GpuPlan::new(cfg, width, height)?;
        let (iw, ih) = plan.input_size();
        let q = plan.guide_channels();
        // Buffers sized for a separate fit guide set (after the output-resolution
        // guides); frames without one use the `planar` parameters instead.
        let separate = GpuLayouts::planar_with_fit(width, height, iw, ih, q, input);
        let params = [plan.params(&GpuLayouts::planar(width, height, input)).ok(), Some(plan.params(&separate)?)];
        let descs = plan.buffers(&separate)?;
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("lrdenoise flr"),
            source: wgpu::ShaderSource::Wgsl(FLR_WGSL.into()),
        });
        let bgl = compute::layout(&device, "lrdenoise flr", descs.iter().map(|d| (d.binding, d.access)));
        let pipelines = compute::pipelines(&device, &module, &bgl, plan.passes().iter().map(|p| (p.name(), p.workgroups)));
        let buffers = descs
            .iter()
            .map(|d| compute::buffer(&device, &format!("lrdenoise flr {:?}", d.buffer), d.access, d.bytes))
            .collect::<Result<Vec<_>, _>>()?;
        let bind_group = compute::bind_group(&device, "lrdenoise flr", &bgl, &buffers.iter().collect::<Vec<_>>());
        let out_bytes = descs[7].bytes.next_multiple_of(4);
        let timer = device.features().contains(wgpu::Features::TIMESTAMP_QUERY).then(|| {
            let set = device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("lrdenoise passes"),
                ty: wgpu::QueryType::Timestamp,
                count: TIMESTAMPS,
            });
            let resolve = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("lrdenoise timestamps"),
                size: TIMESTAMPS as u64 * 8,
                usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            (set, resolve)
        });
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("lrdenoise readback"),
            size: out_bytes + lrdenoise::flr::gpu::STATS_BYTES + TIMESTAMPS as u64 * 8 + EXTRA_BYTES,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Device(e.to_string()));
        }
        let current = if params[0].is_some() { 0 } else { 1 };
        if let Some(p) = params[current] {
            queue.write_buffer(&buffers[0], 0, p.as_bytes());
        }
        Ok(GpuFlr {
            device,
            queue,
            adapter,
            plan,
            pipelines,
            bind_group,
            buffers,
            readback,
            input,
            params,
            current: Some(current),
            timer,
            pass_ms: None,
            noisy: vec![0.0; 3 * iw * ih],
            guides: vec![0.0; q * (width * height + iw * ih)],
            half: Vec::new(),
        })
    }

    /// GPU time of each pass of the last [`GpuFlr::denoise`] (in the order of
    /// [`GpuPlan::passes`]), in milliseconds (timestamp queries; `None` where
    /// the device has none). Their sum is the shader time alone, without
    /// upload, readback or submission.
    pub fn pass_times_ms(&self) -> Option<&[f64]> {
        self.pass_ms.as_deref()
    }

    /// The adapter's name, type and backend.
    pub fn adapter_name(&self) -> &str {
        &self.adapter
    }

    /// The dispatch description this executor runs.
    pub fn plan(&self) -> &GpuPlan {
        &self.plan
    }

    /// Records the passes (on this executor's buffers) into `encoder`:
    /// for callers that fill the input buffers themselves ([`GpuFlr::buffer`]).
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder) {
        for (i, (pipe, [x, y, z])) in self.pipelines.iter().enumerate() {
            // one compute pass per stage: passes are ordered and their storage
            // writes visible to the next
            let timestamp_writes = self.timer.as_ref().map(|(set, _)| wgpu::ComputePassTimestampWrites {
                query_set: set,
                beginning_of_pass_write_index: Some(2 * i as u32),
                end_of_pass_write_index: Some(2 * i as u32 + 1),
            });
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: None, timestamp_writes });
            pass.set_pipeline(pipe);
            pass.set_bind_group(0, &self.bind_group, &[]);
            pass.dispatch_workgroups(*x, *y, *z);
        }
    }

    /// The buffer bound at `binding` (see [`GpuPlan::buffers`]); inputs are
    /// planar in this executor's [`InputFormat`]: [`GpuLayouts::planar`] at
    /// upsample 1 (until a frame with `guides_low` is denoised), else
    /// [`GpuLayouts::planar_with_fit`].
    pub fn buffer(&self, binding: usize) -> Option<&wgpu::Buffer> {
        self.buffers.get(binding)
    }

    /// Denoises one frame: uploads it (any layout, f32 or f16, converted to
    /// planar in this executor's input format), runs the passes, waits and
    /// writes the result into `out`. As on the CPU, `frame.guides_low` is the
    /// guide set the moments are taken from: at the noisy resolution when
    /// upsampling (required then, unless no guides are configured), or a
    /// second full-resolution set at upsample 1 (FLNR).
    pub fn denoise(&mut self, frame: &Frame<'_>, out: &mut ImageViewMut<'_>) -> Result<Report, GpuError> {
        let (w, h) = self.plan.size();
        check_output(out, w, h)?;
        self.upload(frame)?;
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let mut enc = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("lrdenoise flr") });
        self.encode(&mut enc);
        let result = self.buffers[7].clone();
        self.finish(enc, scope, &result, out, None, &mut [])
    }

    /// Checks `frame` and uploads it into the noisy and guide buffers (and
    /// the parameter block its guide sets need).
    fn upload(&mut self, frame: &Frame<'_>) -> Result<(), GpuError> {
        let (w, h) = self.plan.size();
        let (iw, ih) = self.plan.input_size();
        let n = &frame.noisy;
        if (n.width(), n.height()) != (iw, ih) {
            return Err(Error::SizeMismatch { arg: Arg::Noisy, expected: (iw, ih), got: (n.width(), n.height()) }.into());
        }
        if n.channel_count() < 3 {
            return Err(Error::ChannelCount { arg: Arg::Noisy, expected: 3, got: n.channel_count() }.into());
        }
        if frame.sample_weights.is_some() {
            return Err(Error::Unsupported("FLR on the GPU has no per-pixel sample weights (Frame::sample_weights given)").into());
        }
        let set = self.plan.config().guides;
        let q = self.plan.guide_channels();
        let map = frame.guides.channel_views(&set, w, h, Arg::Guide)?;
        let fit = match (self.plan.config().upsample, &frame.guides_low) {
            (1, None) => None,
            (1, Some(low)) => Some(low.channel_views(&set, w, h, Arg::GuideLow)?),
            (_, Some(low)) => Some(low.channel_views(&set, iw, ih, Arg::GuideLow)?),
            (_, None) if q == 0 => None,
            (_, None) => return Err(Error::Unsupported("upsampling needs guides_low at the noisy resolution").into()),
        };
        let mode = fit.is_some() as usize;
        if self.current != Some(mode) {
            let p = self.params[mode].ok_or(Error::Unsupported("upsampling needs guides_low at the noisy resolution"))?;
            self.queue.write_buffer(&self.buffers[0], 0, p.as_bytes());
            self.current = Some(mode);
        }
        let bad = Error::GuideMismatch;
        let (plane, low) = (w * h, iw * ih);
        let (noisy, guides) = (&mut self.noisy, &mut self.guides);
        for y in 0..ih {
            let (r, rest) = noisy.split_at_mut(low);
            let (g, b) = rest.split_at_mut(low);
            let row = y * iw..(y + 1) * iw;
            n.read_row_n(y, 0, [&mut r[row.clone()], &mut g[row.clone()], &mut b[row.clone()]]).ok_or(bad)?;
        }
        let (map_planes, fit_planes) = guides.split_at_mut(q * plane);
        for (c, v) in map.iter().take(q).enumerate() {
            let v = v.ok_or(bad)?;
            for y in 0..h {
                v.read_row(y, 0, 0, &mut map_planes[c * plane + y * w..c * plane + (y + 1) * w]).ok_or(bad)?;
            }
        }
        if let Some(fit) = &fit {
            for (c, v) in fit.iter().take(q).enumerate() {
                let v = v.ok_or(bad)?;
                for y in 0..ih {
                    v.read_row(y, 0, 0, &mut fit_planes[c * low + y * iw..c * low + (y + 1) * iw]).ok_or(bad)?;
                }
            }
        }
        let used = if fit.is_some() { q * (plane + low) } else { q * plane };
        let (noisy, guides) = (&self.noisy[..], &self.guides[..used]);
        for (binding, values) in [(1, noisy), (2, guides)] {
            if values.is_empty() {
                continue;
            }
            match self.input {
                InputFormat::F32 => self.queue.write_buffer(&self.buffers[binding], 0, bytemuck::cast_slice(values)),
                InputFormat::F16 => {
                    self.half.clear();
                    self.half.extend(values.iter().map(|v| half::f16::from_f32(*v)));
                    if self.half.len() % 2 == 1 {
                        self.half.push(half::f16::ZERO); // whole 32-bit words
                    }
                    self.queue.write_buffer(&self.buffers[binding], 0, bytemuck::cast_slice(&self.half));
                }
            }
        }
        Ok(())
    }

    /// Copies `result` (3 f32 planes of the output size), the stats and the
    /// first `extra.len()` (≤ [`EXTRA_BYTES`]) bytes of `extra_from` into the
    /// readback buffer, submits `enc`, waits, writes the planes into `out`,
    /// the extra bytes into `extra` and returns FLR's report.
    fn finish(
        &mut self,
        mut enc: wgpu::CommandEncoder,
        scope: wgpu::ErrorScopeGuard,
        result: &wgpu::Buffer,
        out: &mut ImageViewMut<'_>,
        extra_from: Option<&wgpu::Buffer>,
        extra: &mut [u8],
    ) -> Result<Report, GpuError> {
        let (w, h) = self.plan.size();
        let plane = w * h;
        let out_bytes = self.buffers[7].size();
        enc.copy_buffer_to_buffer(result, 0, &self.readback, 0, out_bytes);
        enc.copy_buffer_to_buffer(&self.buffers[3], 0, &self.readback, out_bytes, lrdenoise::flr::gpu::STATS_BYTES);
        let ts_at = out_bytes + lrdenoise::flr::gpu::STATS_BYTES;
        if let Some((set, resolve)) = &self.timer {
            enc.resolve_query_set(set, 0..TIMESTAMPS, resolve, 0);
            enc.copy_buffer_to_buffer(resolve, 0, &self.readback, ts_at, TIMESTAMPS as u64 * 8);
        }
        let extra_at = ts_at + TIMESTAMPS as u64 * 8;
        if let Some(b) = extra_from {
            enc.copy_buffer_to_buffer(b, 0, &self.readback, extra_at, extra.len().min(EXTRA_BYTES as usize) as u64);
        }
        self.queue.submit([enc.finish()]);
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Device(e.to_string()));
        }
        let (timer, passes) = (self.timer.is_some(), self.pipelines.len());
        let period = self.queue.get_timestamp_period() as f64; // ns per tick
        let mut pass_ms = None;
        let report = compute::read_back(&self.device, &self.readback, |data| {
            let vals: &[f32] = bytemuck::cast_slice(&data[..3 * plane * 4]);
            for y in 0..h {
                let row = y * w..(y + 1) * w;
                out.write_row_n(
                    y,
                    0,
                    [&vals[row.clone()], &vals[plane + y * w..plane + (y + 1) * w], &vals[2 * plane + y * w..2 * plane + (y + 1) * w]],
                )
                .ok_or(Error::InvalidTile { index: y, count: h })?;
            }
            if timer {
                let ticks: &[u8] = &data[ts_at as usize..ts_at as usize + TIMESTAMPS as usize * 8];
                let tick = |j: usize| u64::from_le_bytes(ticks[8 * j..8 * j + 8].try_into().unwrap_or([0; 8]));
                pass_ms = Some((0..passes).map(|i| tick(2 * i + 1).saturating_sub(tick(2 * i)) as f64 * period * 1e-6).collect());
            }
            if extra_from.is_some() {
                let n = extra.len().min(EXTRA_BYTES as usize);
                extra[..n].copy_from_slice(&data[extra_at as usize..extra_at as usize + n]);
            }
            Ok(self.plan.report(&data[out_bytes as usize..]))
        })?;
        if pass_ms.is_some() {
            self.pass_ms = pass_ms;
        }
        Ok(report)
    }
}

/// Checks that `out` is `w × h` with at least 3 channels.
fn check_output(out: &ImageViewMut<'_>, w: usize, h: usize) -> Result<(), GpuError> {
    if out.width() != w || out.height() != h || out.channel_count() < 3 {
        return Err(Error::SizeMismatch { arg: Arg::Output, expected: (w, h), got: (out.width(), out.height()) }.into());
    }
    Ok(())
}

/// A shader module in other languages, translated by naga.
#[derive(Debug)]
pub struct Shaders {
    pub wgsl: &'static str,
    /// SPIR-V words (Vulkan 1.1), one module with every entry point.
    pub spirv: Vec<u32>,
    /// Metal Shading Language source.
    pub msl: String,
    /// HLSL (shader model 5.1) source.
    pub hlsl: String,
}

/// Translates [`FLR_WGSL`] to SPIR-V, MSL and HLSL.
pub fn shaders() -> Result<Shaders, GpuError> {
    translate(FLR_WGSL)
}

/// Validates a WGSL module (FLR's, or the temporal stage's
/// [`lrdenoise::temporal::gpu::TEMPORAL_WGSL`]) and translates it to SPIR-V, MSL and HLSL.
pub fn translate(wgsl: &'static str) -> Result<Shaders, GpuError> {
    let err = |e: &dyn fmt::Display| GpuError::Shader(e.to_string());
    let module = naga::front::wgsl::parse_str(wgsl).map_err(|e| GpuError::Shader(e.emit_to_string(wgsl)))?;
    let info = naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::all())
        .validate(&module)
        .map_err(|e| GpuError::Shader(e.emit_to_string(wgsl)))?;
    let spirv = naga::back::spv::write_vec(&module, &info, &naga::back::spv::Options::default(), None).map_err(|e| err(&e))?;
    let (msl, _) =
        naga::back::msl::write_string(&module, &info, &naga::back::msl::Options::default(), &naga::back::msl::PipelineOptions::default())
            .map_err(|e| err(&e))?;
    let mut hlsl = String::new();
    let opts = naga::back::hlsl::Options::default();
    naga::back::hlsl::Writer::new(&mut hlsl, &opts, &Default::default()).write(&module, &info, None).map_err(|e| err(&e))?;
    Ok(Shaders { wgsl, spirv, msl, hlsl })
}
