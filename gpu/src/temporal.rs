//! Temporal FLR on a `wgpu` device: the temporal stage's shaders
//! ([`lrdenoise::temporal::gpu`]) around FLR's, run as
//! [`GpuTemporalPlan`] describes.

use crate::{check_output, compute, GpuError, GpuFlr};
use lrdenoise::flr::gpu::{Access, InputFormat};
use lrdenoise::temporal::gpu::{GpuTemporalParams, GpuTemporalPlan, TemporalBuffer, COUNTERS_BYTES, TEMPORAL_WGSL};
use lrdenoise::temporal::TemporalConfig;
use lrdenoise::{Arg, Error, FlrConfig, Frame, GuideSet, ImageView, ImageViewMut, Report};

/// Temporal FLR ([`lrdenoise::flr::temporal::TemporalFlr`]) for one frame
/// size on a wgpu device: the history lives on the device, one per
/// executor (one sequence; [`GpuTemporalFlr::reset`] after a cut the stage
/// does not detect).
///
/// ```no_run
/// use lrdenoise::temporal::TemporalConfig;
/// use lrdenoise::{FlrConfig, Frame, Guides, GuideSet, ImageView, ImageViewMut};
/// let (w, h) = (64, 48);
/// let (noisy, normal, depth) = (vec![0.5f32; w * h * 3], vec![0.0f32; w * h * 3], vec![1.0f32; w * h]);
/// let motion = vec![0.0f32; w * h * 2];
/// let cfg = FlrConfig { guides: GuideSet::NORMAL_DEPTH, ..FlrConfig::temporal() };
/// let mut tflr = lrdenoise_gpu::GpuTemporalFlr::new(cfg, TemporalConfig::default(), w, h)?;
/// let mut out = vec![0f32; w * h * 3];
/// for _ in 0..3 {
///     let guides = Guides {
///         normal: Some(ImageView::interleaved(&normal, w, h, 3)?),
///         depth: Some(ImageView::interleaved(&depth, w, h, 1)?),
///         ..Default::default()
///     };
///     let frame = Frame::new(ImageView::interleaved(&noisy, w, h, 3)?, guides);
///     let mv = ImageView::interleaved(&motion, w, h, 2)?;
///     tflr.denoise(&frame, Some(&mv), &mut ImageViewMut::interleaved(&mut out, w, h, 3)?)?;
/// }
/// assert_eq!(tflr.frames(), 3);
/// # Ok::<(), lrdenoise_gpu::GpuError>(())
/// ```
#[derive(Debug)]
pub struct GpuTemporalFlr {
    /// FLR on the accumulated light (its clamp off: the stage clamps).
    flr: GpuFlr,
    plan: GpuTemporalPlan,
    fireflies: Option<f32>,
    clamp_negative: bool,
    /// The passes before FLR's, then the one after.
    pipelines: Vec<(wgpu::ComputePipeline, [u32; 3])>,
    /// The bind group of each read slot (`GpuTemporalPlan::slots`).
    bind_groups: [wgpu::BindGroup; 2],
    /// This executor's own buffers: params, the history's two slots, work (with the motion), counters, output.
    params: wgpu::Buffer,
    slots: [wgpu::Buffer; 2],
    work: wgpu::Buffer,
    output: wgpu::Buffer,
    counters: wgpu::Buffer,
    /// Frames in the history (its parity picks the slots, as on the CPU).
    frames: u32,
    /// Host staging of the motion planes and the work buffer's rejection guides (reused).
    staging: Vec<f32>,
}

impl GpuTemporalFlr {
    /// Plans temporal FLR for `width × height` frames on the default adapter.
    /// As on the CPU, the stage rejects history with the guides of
    /// `cfg.guides` it knows (normal, position, depth) and joint upsampling
    /// is not supported.
    pub fn new(cfg: FlrConfig, temporal: TemporalConfig, width: usize, height: usize) -> Result<Self, GpuError> {
        let (device, queue, name) = crate::default_device()?;
        Self::with_device(device, queue, name, cfg, temporal, width, height)
    }

    /// As [`GpuTemporalFlr::new`] on the caller's device (`adapter` is only a label).
    pub fn with_device(
        device: wgpu::Device,
        queue: wgpu::Queue,
        adapter: String,
        cfg: FlrConfig,
        temporal: TemporalConfig,
        width: usize,
        height: usize,
    ) -> Result<Self, GpuError> {
        if cfg.upsample != 1 {
            return Err(Error::Unsupported("temporal FLR with upsample > 1").into());
        }
        let plan = GpuTemporalPlan::new(temporal, cfg.guides, width, height)?;
        plan.params(0, cfg.fireflies, cfg.clamp_negative)?; // refuses a bad clamp factor here, not at the first frame
        let flr_cfg = FlrConfig { fireflies: None, ..cfg };
        let flr = GpuFlr::with_device(device, queue, adapter, flr_cfg, width, height, InputFormat::F32)?;
        Self::build(flr, plan, cfg.fireflies, cfg.clamp_negative)
    }

    /// The same executor with history taps judged by the normal, position and
    /// depth of `guides` rather than FLR's own, as
    /// [`TemporalFlr::with_rejection_guides`](lrdenoise::flr::temporal::TemporalFlr::with_rejection_guides)
    /// on the CPU (world positions judge a tap by where it is, whatever the
    /// camera did). The frames then carry FLR's guides and these; those FLR
    /// does not read are uploaded next to the motion. The history restarts.
    pub fn with_rejection_guides(self, guides: GuideSet) -> Result<Self, GpuError> {
        let (w, h) = self.flr.plan().size();
        let fit = self.flr.plan().config().guides;
        let plan = GpuTemporalPlan::with_rejection_guides(*self.plan.stage().config(), fit, guides, w, h)?;
        Self::build(self.flr, plan, self.fireflies, self.clamp_negative)
    }

    /// The stage's pipelines and buffers around `flr`.
    fn build(flr: GpuFlr, plan: GpuTemporalPlan, fireflies: Option<f32>, clamp_negative: bool) -> Result<Self, GpuError> {
        let device = flr.device.clone();
        let (width, height) = flr.plan().size();
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("lrdenoise temporal"),
            source: wgpu::ShaderSource::Wgsl(TEMPORAL_WGSL.into()),
        });
        let descs = plan.buffers();
        let bgl = compute::layout(&device, "lrdenoise temporal", descs.iter().map(|d| (d.binding, d.access)));
        let passes = plan.passes_before().into_iter().chain([plan.pass_after()]);
        let pipelines = compute::pipelines(&device, &module, &bgl, passes.map(|p| (p.name(), p.workgroups)));
        let flr_buffer = |binding: usize| flr.buffer(binding).cloned().ok_or(GpuError::Device("FLR's buffers".into()));
        let mut bound = Vec::with_capacity(descs.len());
        for d in &descs {
            bound.push(match d.buffer {
                TemporalBuffer::Light => flr_buffer(1)?,
                TemporalBuffer::Guides => flr_buffer(2)?,
                TemporalBuffer::Fitted => flr_buffer(7)?,
                // the slots, created once each below (read-write: the slot
                // read this frame is the one written the next)
                TemporalBuffer::HistoryIn => compute::buffer(&device, "lrdenoise history slot 0", Access::ReadWriteStorage, d.bytes)?,
                TemporalBuffer::HistoryOut => compute::buffer(&device, "lrdenoise history slot 1", Access::ReadWriteStorage, d.bytes)?,
                _ => compute::buffer(&device, &format!("lrdenoise temporal {:?}", d.buffer), d.access, d.bytes)?,
            });
        }
        let at = |b: TemporalBuffer| bound[b as usize].clone();
        let slots = [at(TemporalBuffer::HistoryIn), at(TemporalBuffer::HistoryOut)];
        // bind_groups[r]: slot r read, the other written
        let bind_groups = [0, 1].map(|r| {
            let mut list: Vec<&wgpu::Buffer> = bound.iter().collect();
            list[TemporalBuffer::HistoryIn as usize] = &slots[r];
            list[TemporalBuffer::HistoryOut as usize] = &slots[1 - r];
            compute::bind_group(&device, "lrdenoise temporal", &bgl, &list)
        });
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Device(e.to_string()));
        }
        let work_planes = 2 + plan.work_guides().iter().zip([3, 3, 1]).map(|(g, n)| if g.is_some() { n } else { 0 }).sum::<usize>();
        Ok(GpuTemporalFlr {
            plan,
            fireflies,
            clamp_negative,
            pipelines,
            bind_groups,
            params: at(TemporalBuffer::Params),
            work: at(TemporalBuffer::Work),
            slots,
            output: at(TemporalBuffer::Output),
            counters: at(TemporalBuffer::Counters),
            frames: 0,
            staging: vec![0.0; work_planes * width * height],
            flr,
        })
    }

    /// The dispatch description of the temporal stage this executor runs.
    pub fn plan(&self) -> &GpuTemporalPlan {
        &self.plan
    }

    /// The guides each frame carries: FLR's and the stage's rejection guides.
    pub fn frame_guides(&self) -> GuideSet {
        self.flr.plan().config().guides.with_geometry_of(self.plan.stage().rejection_guides())
    }

    /// The FLR executor inside (its adapter, its plan, its pass times).
    pub fn flr(&self) -> &GpuFlr {
        &self.flr
    }

    /// Frames accumulated in the history.
    pub fn frames(&self) -> u32 {
        self.frames
    }

    /// Forgets the history: the next frame starts a sequence.
    pub fn reset(&mut self) {
        self.frames = 0;
    }

    /// f32 values of the history (the CPU stage's [`lrdenoise::temporal::Reprojection::history_len`]).
    pub fn history_len(&self) -> usize {
        self.plan.stage().history_len()
    }

    /// Copies the history into `dst` ([`GpuTemporalFlr::history_len`] values,
    /// the CPU stage's layout) and returns the frame count: with
    /// [`GpuTemporalFlr::set_history`], a sequence can move between the GPU
    /// and the CPU (`History::resume(dst, frames)`) or restart from a saved state.
    pub fn history(&self, dst: &mut [f32]) -> Result<u32, GpuError> {
        let n = self.history_len();
        if dst.len() != n {
            return Err(Error::BufferTooSmall { arg: Arg::History, needed: n, len: dst.len() }.into());
        }
        let device = &self.flr.device;
        let slot_bytes = self.slots[0].size();
        let staging = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("lrdenoise history readback"),
            size: 2 * slot_bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut enc = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("lrdenoise history") });
        enc.copy_buffer_to_buffer(&self.slots[0], 0, &staging, 0, slot_bytes);
        enc.copy_buffer_to_buffer(&self.slots[1], 0, &staging, slot_bytes, slot_bytes);
        self.flr.queue.submit([enc.finish()]);
        let slot = n / 2;
        compute::read_back(device, &staging, |data| {
            let values: &[f32] = bytemuck::cast_slice(data);
            dst[..slot].copy_from_slice(&values[..slot]);
            dst[slot..].copy_from_slice(&values[slot_bytes as usize / 4..][..slot]);
            Ok(())
        })?;
        Ok(self.frames)
    }

    /// Replaces the history with `src` (the CPU stage's layout, as
    /// [`GpuTemporalFlr::history`] or a CPU `History` left it) after `frames`
    /// frames, and waits until the device holds it.
    pub fn set_history(&mut self, src: &[f32], frames: u32) -> Result<(), GpuError> {
        let n = self.history_len();
        if src.len() != n {
            return Err(Error::BufferTooSmall { arg: Arg::History, needed: n, len: src.len() }.into());
        }
        let (a, b) = src.split_at(n / 2);
        self.flr.queue.write_buffer(&self.slots[0], 0, bytemuck::cast_slice(a));
        self.flr.queue.write_buffer(&self.slots[1], 0, bytemuck::cast_slice(b));
        self.flr.queue.submit([]);
        self.flr.device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| GpuError::Device(e.to_string()))?;
        self.frames = frames;
        Ok(())
    }

    /// One frame of the sequence: uploads it and its motion (2 channels,
    /// previous − current pixel position; `None`: a static camera), runs the
    /// stage and FLR, waits and writes the result into `out`. The report
    /// holds the stage's counts and FLR's, as on the CPU.
    pub fn denoise(&mut self, frame: &Frame<'_>, motion: Option<&ImageView<'_>>, out: &mut ImageViewMut<'_>) -> Result<Report, GpuError> {
        let (w, h) = self.flr.plan().size();
        check_output(out, w, h)?;
        if frame.guides_low.is_some() {
            return Err(Error::Unsupported("temporal FLR with a second (low-resolution) guide set").into());
        }
        let plane = w * h;
        match motion {
            Some(m) => {
                if (m.width(), m.height()) != (w, h) {
                    return Err(Error::SizeMismatch { arg: Arg::Motion, expected: (w, h), got: (m.width(), m.height()) }.into());
                }
                if m.channel_count() < 2 {
                    return Err(Error::ChannelCount { arg: Arg::Motion, expected: 2, got: m.channel_count() }.into());
                }
                let (mx, rest) = self.staging.split_at_mut(plane);
                let my = &mut rest[..plane];
                for y in 0..h {
                    let row = y * w..(y + 1) * w;
                    m.read_row_n(y, 0, [&mut mx[row.clone()], &mut my[row]]).ok_or(Error::InvalidTile { index: y, count: h })?;
                }
            }
            None => self.staging[..2 * plane].fill(0.0),
        }
        // the rejection guides FLR does not read, after the motion
        let g = &frame.guides;
        for ((at, view), channels) in self.plan.work_guides().into_iter().zip([g.normal, g.position, g.depth]).zip([3, 3, 1]) {
            let Some(at) = at else { continue };
            let v = view.ok_or(Error::GuideMismatch)?;
            if (v.width(), v.height()) != (w, h) {
                return Err(Error::SizeMismatch { arg: Arg::Guide, expected: (w, h), got: (v.width(), v.height()) }.into());
            }
            if v.channel_count() < channels {
                return Err(Error::ChannelCount { arg: Arg::Guide, expected: channels, got: v.channel_count() }.into());
            }
            let first = (at - self.plan.motion_offset()) as usize / 4;
            let planes = &mut self.staging[first..first + channels * plane];
            for y in 0..h {
                for c in 0..channels {
                    let row = c * plane + y * w;
                    v.read_row(y, c, 0, &mut planes[row..row + w]).ok_or(Error::InvalidTile { index: y, count: h })?;
                }
            }
        }
        let params: GpuTemporalParams = self.plan.params(self.frames, self.fireflies, self.clamp_negative)?;
        // FLR reads its own guides only (the rejection guides beyond them are in the work buffer)
        let fit_set = self.flr.plan().config().guides;
        let mut fit = frame.guides;
        fit.normal = fit.normal.filter(|_| fit_set.normal);
        fit.position = fit.position.filter(|_| fit_set.position);
        fit.depth = fit.depth.filter(|_| fit_set.depth);
        self.flr.upload(&Frame { guides: fit, ..*frame })?;
        let queue = &self.flr.queue;
        queue.write_buffer(&self.work, self.plan.motion_offset(), bytemuck::cast_slice(&self.staging));
        queue.write_buffer(&self.params, 0, params.as_bytes());
        let (read_slot, _) = GpuTemporalPlan::slots(self.frames);
        let device = self.flr.device.clone();
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let mut enc = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("lrdenoise temporal flr") });
        let dispatch = |enc: &mut wgpu::CommandEncoder, (pipe, [x, y, z]): &(wgpu::ComputePipeline, [u32; 3])| {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor { label: None, timestamp_writes: None });
            pass.set_pipeline(pipe);
            pass.set_bind_group(0, &self.bind_groups[read_slot], &[]);
            pass.dispatch_workgroups(*x, *y, *z);
        };
        let (before, after) = self.pipelines.split_at(4);
        for p in before {
            dispatch(&mut enc, p);
        }
        self.flr.encode(&mut enc);
        for p in after {
            dispatch(&mut enc, p);
        }
        let mut counters = [0u8; COUNTERS_BYTES as usize];
        let (output, counters_buf) = (self.output.clone(), self.counters.clone());
        let fit = self.flr.finish(enc, scope, &output, out, Some(&counters_buf), &mut counters)?;
        let c = self.plan.counts(&counters, &params);
        self.frames = if self.frames == u32::MAX { 2 } else { self.frames + 1 };
        // FLR's report but for the NaN/Inf samples: the stage counted (and bridged) those
        Ok(Report {
            history_rejected: c.rejected,
            invalid_motion: c.invalid_motion,
            history_resets: c.cut,
            nonfinite_noisy: c.nonfinite,
            clamped_fireflies: c.clamped,
            ..fit
        })
    }
}
