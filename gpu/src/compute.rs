//! What FLR's and the temporal stage's executors share: buffers checked
//! against the device's limits, a bind-group layout from access kinds, one
//! compute pipeline per entry point.

use crate::GpuError;
use lrdenoise::flr::gpu::Access;

/// Creates a buffer of `bytes` (rounded up to 4) bound as `access`, or
/// [`GpuError::TooLarge`] when the device's limits cannot hold it.
pub(crate) fn buffer(device: &wgpu::Device, name: &str, access: Access, bytes: u64) -> Result<wgpu::Buffer, GpuError> {
    let size = bytes.next_multiple_of(4).max(4);
    let limits = device.limits();
    let binding_limit = match access {
        Access::Uniform => limits.max_uniform_buffer_binding_size,
        _ => limits.max_storage_buffer_binding_size,
    };
    let limit = binding_limit.min(limits.max_buffer_size);
    if size > limit {
        return Err(GpuError::TooLarge { buffer: name.to_string(), bytes: size, limit });
    }
    let usage = match access {
        Access::Uniform => wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        _ => wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
    };
    Ok(device.create_buffer(&wgpu::BufferDescriptor { label: Some(name), size, usage, mapped_at_creation: false }))
}

/// A bind-group layout of group 0 with one buffer per `(binding, access)`.
pub(crate) fn layout(device: &wgpu::Device, label: &str, bindings: impl Iterator<Item = (u32, Access)>) -> wgpu::BindGroupLayout {
    let entries: Vec<wgpu::BindGroupLayoutEntry> = bindings
        .map(|(binding, access)| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty: match access {
                    Access::Uniform => wgpu::BufferBindingType::Uniform,
                    Access::ReadOnlyStorage => wgpu::BufferBindingType::Storage { read_only: true },
                    Access::ReadWriteStorage => wgpu::BufferBindingType::Storage { read_only: false },
                },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        })
        .collect();
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(label), entries: &entries })
}

/// A bind group binding `buffers[i]` whole at binding `i`.
pub(crate) fn bind_group(device: &wgpu::Device, label: &str, layout: &wgpu::BindGroupLayout, buffers: &[&wgpu::Buffer]) -> wgpu::BindGroup {
    let entries: Vec<wgpu::BindGroupEntry> =
        buffers.iter().enumerate().map(|(i, b)| wgpu::BindGroupEntry { binding: i as u32, resource: b.as_entire_binding() }).collect();
    device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some(label), layout, entries: &entries })
}

/// One compute pipeline per `(entry point, workgroups)` of `module`, all with `layout`.
pub(crate) fn pipelines<'a>(
    device: &wgpu::Device,
    module: &wgpu::ShaderModule,
    layout: &wgpu::BindGroupLayout,
    passes: impl Iterator<Item = (&'a str, [u32; 3])>,
) -> Vec<(wgpu::ComputePipeline, [u32; 3])> {
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: None,
        bind_group_layouts: &[Some(layout)],
        immediate_size: 0,
    });
    passes
        .map(|(entry, workgroups)| {
            let pipe = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: Some(&pipeline_layout),
                module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            });
            (pipe, workgroups)
        })
        .collect()
}

/// Maps `buffer` (submitted work must have written it), waits, passes its
/// bytes to `read` and unmaps it, on every path where the map succeeded.
pub(crate) fn read_back<T>(
    device: &wgpu::Device,
    buffer: &wgpu::Buffer,
    read: impl FnOnce(&[u8]) -> Result<T, GpuError>,
) -> Result<T, GpuError> {
    let device_error = |e: &dyn std::fmt::Display| GpuError::Device(e.to_string());
    let (tx, rx) = std::sync::mpsc::channel();
    buffer.map_async(wgpu::MapMode::Read, .., move |r| {
        let _ = tx.send(r);
    });
    let polled = device.poll(wgpu::PollType::wait_indefinitely());
    match rx.try_recv() {
        Ok(Ok(())) => {}
        Ok(Err(e)) => return Err(device_error(&e)),
        Err(e) => return Err(polled.err().map_or_else(|| device_error(&e), |p| device_error(&p))),
    }
    let result = match buffer.get_mapped_range(..) {
        Ok(data) => read(&data),
        Err(e) => Err(device_error(&e)),
    };
    buffer.unmap();
    result
}
