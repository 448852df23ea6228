//! Small helpers for labelled buffers and read-backs.

use crate::{Error, Result};
use wgpu::util::DeviceExt;

/// A storage buffer holding `data` (at least one element and 16 bytes, so that empty
/// tables still bind).
pub fn storage_init<T: bytemuck::Pod>(
    device: &wgpu::Device,
    label: &str,
    data: &[T],
    extra: wgpu::BufferUsages,
) -> wgpu::Buffer {
    let bytes: &[u8] = bytemuck::cast_slice(data);
    let mut contents = bytes.to_vec();
    let least = std::mem::size_of::<T>().max(16);
    if contents.len() < least {
        contents.resize(least, 0);
    }
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents: &contents,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | extra,
    })
}

/// A zeroed storage buffer of `size` bytes (rounded up to 16).
pub fn storage_zeroed(device: &wgpu::Device, label: &str, size: u64, extra: wgpu::BufferUsages) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: size.max(16).next_multiple_of(16),
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | extra,
        mapped_at_creation: false,
    })
}

/// A uniform buffer for one `T`, written with `queue.write_buffer`.
pub fn uniform<T: bytemuck::Pod>(device: &wgpu::Device, label: &str, value: &T) -> wgpu::Buffer {
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents: bytemuck::bytes_of(value),
        usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
    })
}

/// Copies `size` bytes of `buffer` (which needs COPY_SRC) back to the host and waits.
pub fn read_back<T: bytemuck::Pod>(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    buffer: &wgpu::Buffer,
    size: u64,
) -> Result<Vec<T>> {
    read_back_at(device, queue, buffer, 0, size)
}

/// As `read_back`, from byte `offset` (a multiple of 4) of `buffer`.
pub fn read_back_at<T: bytemuck::Pod>(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    buffer: &wgpu::Buffer,
    offset: u64,
    size: u64,
) -> Result<Vec<T>> {
    let mut out = Vec::new();
    read_back_into(device, queue, buffer, offset, size, &mut out)?;
    Ok(out)
}

/// As `read_back_at`, appending to `out`: straight from the mapped staging memory, with no
/// copy in between (a large image's sums are gigabytes: each copy of them costs seconds).
pub fn read_back_into<T: bytemuck::Pod>(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    buffer: &wgpu::Buffer,
    offset: u64,
    size: u64,
    out: &mut Vec<T>,
) -> Result<()> {
    let staging = staging_buffer(device, size);
    read_back_via(device, queue, buffer, offset, size, &staging, out)
}

/// A buffer to read back through, of `size` bytes (`read_back_via`).
pub fn staging_buffer(device: &wgpu::Device, size: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("firstshot.readback"),
        size: size.next_multiple_of(4).max(4),
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

/// As `read_back_into`, through `staging` (`staging_buffer`, at least `size` bytes): reading
/// many buffers through one staging buffer allocates the mapped memory once (on a GPU, pinned
/// host memory, which is slow to allocate).
pub fn read_back_via<T: bytemuck::Pod>(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    buffer: &wgpu::Buffer,
    offset: u64,
    size: u64,
    staging: &wgpu::Buffer,
    out: &mut Vec<T>,
) -> Result<()> {
    let size = size.next_multiple_of(4);
    if staging.size() < size {
        return Err(Error::Gpu(format!("read-back: a staging buffer of {} bytes for {size}", staging.size())));
    }
    let mut encoder =
        device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("firstshot.readback") });
    encoder.copy_buffer_to_buffer(buffer, offset, staging, 0, size);
    queue.submit([encoder.finish()]);
    let slice = staging.slice(..size);
    let (tx, rx) = std::sync::mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| Error::Gpu(format!("read-back: {e}")))?;
    rx.recv().map_err(|e| Error::Gpu(format!("read-back: {e}")))?.map_err(|e| Error::Gpu(format!("read-back: {e}")))?;
    let data = slice.get_mapped_range().map_err(|e| Error::Gpu(format!("read-back: {e}")))?;
    out.extend_from_slice(bytemuck::cast_slice::<u8, T>(
        &data[..(size as usize / std::mem::size_of::<T>()) * std::mem::size_of::<T>()],
    ));
    drop(data);
    staging.unmap();
    Ok(())
}
