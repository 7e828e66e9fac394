//! The wgpu instance, adapter, device and queue, for headless and browser use.

/// Why a GPU context could not be created.
#[derive(Debug, thiserror::Error)]
pub enum ContextError {
    /// No adapter at all (no GPU, no lavapipe, no WebGPU).
    #[error("no GPU adapter found ({0}); natively install Mesa's Vulkan drivers (`apt-get install mesa-vulkan-drivers libvulkan1`), in a browser enable WebGPU")]
    NoAdapter(String),
    /// The adapter refused the device request.
    #[error("the GPU adapter refused to create a device: {0}")]
    Device(String),
}

/// A device and queue with the adapter they came from.
pub struct GpuContext {
    /// The wgpu instance.
    pub instance: wgpu::Instance,
    /// The adapter in use.
    pub adapter: wgpu::Adapter,
    /// The device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
}

impl GpuContext {
    /// Creates a context without a surface. Prefers a real GPU and falls back
    /// to any adapter (lavapipe on CI). Requests WebGPU's default limits only,
    /// so what runs here runs in a browser.
    ///
    /// # Errors
    /// [`ContextError`] when there is no adapter or the device request fails.
    pub async fn new_headless() -> Result<Self, ContextError> {
        let (instance, adapter) = Self::headless_adapter().await?;
        let (device, queue) = request_device(&adapter).await?;
        Ok(Self { instance, adapter, device, queue })
    }

    /// The instance and adapter [`Self::new_headless`] takes, without a device:
    /// what a result computed on the GPU depends on (the bake's pack cache
    /// keys its packs by it).
    ///
    /// # Errors
    /// [`ContextError::NoAdapter`] when there is none.
    pub async fn headless_adapter() -> Result<(wgpu::Instance, wgpu::Adapter), ContextError> {
        let mut descriptor = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
        // Debug builds ask for shader debug info by default: naga then writes
        // every expression's source line into the SPIR-V, finding each line
        // by a scan of the source (quadratic in a shader's length), which was
        // 60 % of a GPU test's time (docs/BENCHMARKS.md, "The test suite's
        // time"). Only where asked for (WGPU_DEBUG=1, e.g. for RenderDoc).
        if std::env::var_os("WGPU_DEBUG").is_none() {
            descriptor.flags.remove(wgpu::InstanceFlags::DEBUG);
        }
        let instance = wgpu::Instance::new(descriptor);
        let mut last_err = String::new();
        let mut adapter = None;
        for power in [wgpu::PowerPreference::HighPerformance, wgpu::PowerPreference::None] {
            match instance
                .request_adapter(&wgpu::RequestAdapterOptions { power_preference: power, ..Default::default() })
                .await
            {
                Ok(a) => {
                    adapter = Some(a);
                    break;
                }
                Err(e) => last_err = e.to_string(),
            }
        }
        let adapter = adapter.ok_or(ContextError::NoAdapter(last_err))?;
        Ok((instance, adapter))
    }

    /// Blocking [`Self::new_headless`] for native code.
    ///
    /// # Errors
    /// See [`Self::new_headless`].
    #[cfg(not(target_arch = "wasm32"))]
    pub fn new_headless_blocking() -> Result<Self, ContextError> {
        pollster::block_on(Self::new_headless())
    }

    /// A one-line description of the adapter (name, backend, type).
    #[must_use]
    pub fn adapter_summary(&self) -> String {
        let info = self.adapter.get_info();
        format!("{} ({:?}, {:?})", info.name, info.backend, info.device_type)
    }
}

/// The device every Sylva context asks for: WebGPU's default limits (raised only
/// as far as the adapter's resolution) and no optional feature a pass needs, so
/// what runs natively also runs in a browser. `TIMESTAMP_QUERY` is asked for
/// where the adapter has it, only to time the passes (the browser's stats), and
/// `PIPELINE_STATISTICS_QUERY` (native only) for the bake's work counts, and
/// `TEXTURE_COMPRESSION_BC` and `TEXTURE_COMPRESSION_ETC2` for packs' BC7 and
/// ETC2 variants where the adapter samples them.
///
/// # Errors
/// [`ContextError::Device`] when the adapter refuses.
pub async fn request_device(adapter: &wgpu::Adapter) -> Result<(wgpu::Device, wgpu::Queue), ContextError> {
    adapter
        .request_device(&wgpu::DeviceDescriptor {
            label: Some("sylva"),
            // Timestamp queries only to time the passes (the browser's stats);
            // pipeline statistics only for the bake's LoD policy (work counts);
            // BC and ETC2 textures for packs' block-compressed variants
            // (desktop GPUs; phones, tablets and Apple silicon).
            required_features: adapter.features()
                & (wgpu::Features::TIMESTAMP_QUERY
                    | wgpu::Features::PIPELINE_STATISTICS_QUERY
                    | wgpu::Features::TEXTURE_COMPRESSION_BC
                    | wgpu::Features::TEXTURE_COMPRESSION_ETC2),
            required_limits: wgpu::Limits::default().using_resolution(adapter.limits()),
            experimental_features: wgpu::ExperimentalFeatures::disabled(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        })
        .await
        .map_err(|e| ContextError::Device(e.to_string()))
}

/// Reads back a 2D RGBA8 texture (or one layer of an array) as tightly packed rows.
/// Native only: it blocks on the GPU.
#[cfg(not(target_arch = "wasm32"))]
#[must_use]
pub fn read_texture_rgba8(ctx: &GpuContext, texture: &wgpu::Texture, layer: u32, mip: u32) -> Vec<u8> {
    let width = (texture.width() >> mip).max(1);
    let height = (texture.height() >> mip).max(1);
    // Buffer copies need rows aligned to 256 bytes.
    let padded_row = (width * 4).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
    let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size: u64::from(padded_row) * u64::from(height),
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    encoder.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level: mip,
            origin: wgpu::Origin3d { x: 0, y: 0, z: layer },
            aspect: wgpu::TextureAspect::All,
        },
        wgpu::TexelCopyBufferInfo {
            buffer: &buffer,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(padded_row),
                rows_per_image: Some(height),
            },
        },
        wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
    );
    ctx.queue.submit([encoder.finish()]);
    let slice = buffer.slice(..);
    slice.map_async(wgpu::MapMode::Read, |r| r.expect("map readback buffer"));
    ctx.device.poll(wgpu::PollType::wait_indefinitely()).expect("wait for the GPU");
    let mapped = slice.get_mapped_range().expect("mapped range");
    let mut out = Vec::with_capacity((width * height * 4) as usize);
    for row in mapped.chunks(padded_row as usize).take(height as usize) {
        out.extend_from_slice(&row[..(width * 4) as usize]);
    }
    drop(mapped);
    buffer.unmap();
    out
}

/// Gives the process a private runtime folder when `XDG_RUNTIME_DIR` is unset
/// or names no folder. Without one, Mesa's Vulkan driver prints "error:
/// XDG_RUNTIME_DIR is invalid or not set in the environment." on headless
/// machines, on runs that work. Call first thing in `main`, before threads.
#[cfg(all(unix, not(target_arch = "wasm32")))]
pub fn ensure_runtime_dir() {
    use std::os::unix::fs::{MetadataExt, PermissionsExt};
    let usable = std::env::var_os("XDG_RUNTIME_DIR").is_some_and(|p| std::fs::metadata(p).is_ok_and(|m| m.is_dir()));
    if usable {
        return;
    }
    let Ok(uid) = std::fs::metadata("/proc/self").map(|m| m.uid()) else { return };
    let dir = std::env::temp_dir().join(format!("sylva-xdg-{uid}"));
    let _ = std::fs::create_dir(&dir);
    // Only a folder of ours, closed to others (as the XDG spec asks).
    if std::fs::symlink_metadata(&dir).is_ok_and(|m| m.is_dir() && m.uid() == uid)
        && std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o700)).is_ok()
    {
        std::env::set_var("XDG_RUNTIME_DIR", &dir);
    }
}

/// Elsewhere there is no such variable to set.
#[cfg(not(any(unix, target_arch = "wasm32")))]
pub fn ensure_runtime_dir() {}
