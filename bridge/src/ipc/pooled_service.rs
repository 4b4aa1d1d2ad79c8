//! The iceoryx2 service flavour of the real-time publisher: `ipc_threadsafe` with one
//! building block changed, so that loaning and sending a sample allocate nothing.
//!
//! Where iceoryx2 0.10 allocates per sample (read from its sources):
//! `Publisher::loan_uninit` -> `SampleMutUninit::new` -> `ChunkMutSharedState::new`
//! -> `Service::ArcThreadSafetyPolicy::new`, which for `ipc_threadsafe` is
//! `MutexProtected::new` = `Arc::new(MutexHandle::new())` (`iceoryx2-cal`,
//! `arc_sync_policy/mutex_protected.rs`); the `Arc` is freed when the sample is sent
//! (`SampleMut::send` consumes the sample). `send` and `Notifier::notify` themselves do
//! not allocate once the connections are up. iceoryx2 has no loan without that
//! `Arc`, but the policy is a type of the `Service` trait: [`PooledSvc`] is
//! `ipc_threadsafe` with [`PooledArc`], the same recursive process-local mutex in a
//! block that is recycled instead of freed. After the first sample the blocks come
//! from the recycling slots: no heap allocation, no free.
//!
//! Every other building block is `ipc_threadsafe`'s, so the shared-memory layout is
//! the same and the estimator (on [`super::Svc`]) talks to this publisher unchanged.

use core::alloc::Layout;
use core::fmt::Debug;
use core::ops::Deref;
use core::ptr::NonNull;
use core::sync::atomic::{fence, AtomicPtr, AtomicU8, AtomicUsize, Ordering};

use iceoryx2_bb_elementary_traits::testing::abandonable::Abandonable;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use iceoryx2_bb_posix::ipc_capable::Handle;
use iceoryx2_bb_posix::mutex::{Mutex, MutexBuilder, MutexGuard, MutexHandle, MutexType};
use iceoryx2_cal::arc_sync_policy::{ArcSyncPolicy, ArcSyncPolicyCreationError, LockGuard};
use iceoryx2_cal::shm_allocator::bump_allocator::BumpAllocator;
use iceoryx2_cal::shm_allocator::pool_allocator::PoolAllocator;
use iceoryx2_cal::*;

/// `ipc_threadsafe::Service` with [`PooledArc`] as its thread-safety policy.
#[derive(Debug, Clone)]
pub struct PooledSvc {}

impl iceoryx2::service::Service for PooledSvc {
    type StaticStorage = static_storage::recommended::Ipc;
    type ConfigSerializer = serialize::recommended::Recommended;
    type PersistentDynamicStorage<T: Debug + Send + Sync + ZeroCopySend + 'static> =
        dynamic_storage::recommended::PersistentIpc<T>;
    type Bag = bag::recommended::Recommended;
    type DynamicStorage<T: Debug + Send + Sync + ZeroCopySend + 'static> =
        dynamic_storage::recommended::Ipc<T>;
    type ServiceNameHasher = hash::recommended::Recommended;
    type SharedMemory = shared_memory::recommended::Ipc<PoolAllocator>;
    type ResizableSharedMemory = resizable_shared_memory::recommended::Ipc<PoolAllocator>;
    type Connection = zero_copy_connection::recommended::Ipc;
    type Event = event::recommended::Ipc;
    type Monitoring = monitoring::recommended::Ipc;
    type Reactor = reactor::recommended::Ipc;
    type ArcThreadSafetyPolicy<T: Send + Debug + Abandonable> = PooledArc<T>;
    type BlackboardMgmt<KeyType: Send + Sync + Debug + ZeroCopySend + 'static> =
        dynamic_storage::recommended::Ipc<KeyType>;
    type BlackboardPayload = shared_memory::recommended::Ipc<BumpAllocator>;
    type UniqueId = iceoryx2::unique_id_generator::unique_system_id::UniqueSystemId;
}

impl iceoryx2::service::internal::ServiceInternal<PooledSvc> for PooledSvc {}

/// Blocks kept for reuse (a publisher, its data segment, a loaned sample, ports: a
/// few are live at once; the rest of a burst is freed).
const SLOTS: usize = 32;
/// Every block is aligned to a cache line, so blocks of one size are interchangeable.
const BLOCK_ALIGN: usize = 64;

const EMPTY: u8 = 0;
const BUSY: u8 = 1;
const FULL: u8 = 2;

/// One recycling slot: a free block and its size. `state` guards the two others.
struct Slot {
    state: AtomicU8,
    size: AtomicUsize,
    block: AtomicPtr<u8>,
}

#[allow(clippy::declare_interior_mutable_const)]
const SLOT: Slot = Slot {
    state: AtomicU8::new(EMPTY),
    size: AtomicUsize::new(0),
    block: AtomicPtr::new(core::ptr::null_mut()),
};

static SLOTS_OF_PROCESS: [Slot; SLOTS] = [SLOT; SLOTS];

/// A free block of `size` bytes from the slots (lock-free: compare-and-swap on each
/// slot's state), if one is there.
fn take(size: usize) -> Option<*mut u8> {
    for s in &SLOTS_OF_PROCESS {
        if s.state
            .compare_exchange(FULL, BUSY, Ordering::Acquire, Ordering::Relaxed)
            .is_ok()
        {
            if s.size.load(Ordering::Relaxed) == size {
                let block = s.block.load(Ordering::Relaxed);
                s.state.store(EMPTY, Ordering::Release);
                return Some(block);
            }
            s.state.store(FULL, Ordering::Release);
        }
    }
    None
}

/// Keeps `block` for reuse; false when every slot is taken (the caller frees it).
fn keep(block: *mut u8, size: usize) -> bool {
    for s in &SLOTS_OF_PROCESS {
        if s.state
            .compare_exchange(EMPTY, BUSY, Ordering::Acquire, Ordering::Relaxed)
            .is_ok()
        {
            s.size.store(size, Ordering::Relaxed);
            s.block.store(block, Ordering::Relaxed);
            s.state.store(FULL, Ordering::Release);
            return true;
        }
    }
    false
}

struct Inner<T: Send + Debug> {
    refs: AtomicUsize,
    handle: MutexHandle<T>,
}

/// A reference-counted value behind a recursive process-local mutex (as iceoryx2's
/// `MutexProtected`), in a block recycled through the slots instead of freed.
pub struct PooledArc<T: Send + Debug + Abandonable> {
    inner: NonNull<Inner<T>>,
}

// SAFETY: as `MutexProtected`: the value is only reached through the mutex, and the
// count is atomic.
unsafe impl<T: Send + Debug + Abandonable> Send for PooledArc<T> {}
// SAFETY: as above.
unsafe impl<T: Send + Debug + Abandonable> Sync for PooledArc<T> {}

impl<T: Send + Debug + Abandonable> PooledArc<T> {
    fn layout() -> Layout {
        // Inner<T> is at most a few hundred bytes: the alignment is always valid.
        Layout::new::<Inner<T>>()
            .align_to(BLOCK_ALIGN)
            .map_or(Layout::new::<Inner<T>>(), |l| l.pad_to_align())
    }

    fn inner(&self) -> &Inner<T> {
        // SAFETY: the block lives while a reference (self) counts it.
        unsafe { self.inner.as_ref() }
    }

    /// Drops the value and recycles (or frees) the block.
    ///
    /// # Safety
    /// The last reference, given up.
    unsafe fn release(&mut self) {
        let layout = Self::layout();
        let block = self.inner.as_ptr();
        // SAFETY: the last reference: nobody else reaches the value.
        unsafe { core::ptr::drop_in_place(block) };
        let block = block.cast::<u8>();
        if layout.align() != BLOCK_ALIGN || !keep(block, layout.size()) {
            // SAFETY: allocated with this layout in `new`.
            unsafe { std::alloc::dealloc(block, layout) };
        }
    }
}

impl<T: Send + Debug + Abandonable> Clone for PooledArc<T> {
    fn clone(&self) -> Self {
        self.inner().refs.fetch_add(1, Ordering::Relaxed);
        Self { inner: self.inner }
    }
}

impl<T: Send + Debug + Abandonable> Drop for PooledArc<T> {
    fn drop(&mut self) {
        if self.inner().refs.fetch_sub(1, Ordering::Release) == 1 {
            fence(Ordering::Acquire);
            // SAFETY: the count went to zero: this was the last reference.
            unsafe { self.release() };
        }
    }
}

impl<T: Send + Debug + Abandonable> Debug for PooledArc<T> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("PooledArc")
            .field("refs", &self.inner().refs.load(Ordering::Relaxed))
            .finish()
    }
}

impl<T: Send + Debug + Abandonable> Abandonable for PooledArc<T> {
    unsafe fn abandon_in_place(this: NonNull<Self>) {
        // SAFETY: `this` points to a valid PooledArc (the trait's contract).
        let this = unsafe { &mut *this.as_ptr() };
        if this.inner().refs.load(Ordering::Acquire) == 1 {
            // As `MutexProtected`: the only owner abandons the value in place.
            let guard = this.lock();
            // SAFETY: the value stays where it is and is never used again.
            unsafe { T::abandon_in_place(NonNull::from(&*guard)) };
            core::mem::forget(guard);
        } else {
            // SAFETY: gives up this reference as drop would.
            unsafe { core::ptr::drop_in_place(this) };
        }
    }
}

/// The value while the mutex is held.
pub struct PooledGuard<'parent, T: Send + Debug> {
    guard: MutexGuard<'parent, T>,
}

impl<T: Send + Debug> Deref for PooledGuard<'_, T> {
    type Target = T;

    fn deref(&self) -> &T {
        self.guard.deref()
    }
}

impl<'parent, T: Send + Debug + Abandonable> LockGuard<'parent, T> for PooledGuard<'parent, T> {}

impl<T: Send + Debug + Abandonable> ArcSyncPolicy<T> for PooledArc<T> {
    type LockGuard<'parent>
        = PooledGuard<'parent, T>
    where
        Self: 'parent,
        T: 'parent;

    fn new(value: T) -> Result<Self, ArcSyncPolicyCreationError> {
        let layout = Self::layout();
        let block = match take(layout.size()).filter(|_| layout.align() == BLOCK_ALIGN) {
            Some(b) => b,
            // SAFETY: a non-zero size (Inner holds a mutex).
            None => unsafe { std::alloc::alloc(layout) },
        };
        let Some(inner) = NonNull::new(block.cast::<Inner<T>>()) else {
            return Err(ArcSyncPolicyCreationError::InsufficientResources);
        };
        // SAFETY: a block of Inner<T>'s size and alignment that nobody else uses;
        // the mutex is initialised where it stays.
        unsafe {
            inner.as_ptr().write(Inner {
                refs: AtomicUsize::new(1),
                handle: MutexHandle::new(),
            })
        };
        let this = Self { inner };
        let created = MutexBuilder::new()
            .is_interprocess_capable(false)
            .mutex_type(MutexType::Recursive)
            .create(value, &this.inner().handle)
            .is_ok();
        if created {
            Ok(this)
        } else {
            Err(ArcSyncPolicyCreationError::InternalFailure)
        }
    }

    fn lock(&self) -> Self::LockGuard<'_> {
        // SAFETY: the handle was initialised in `new`.
        let mutex = unsafe { Mutex::from_handle(&self.inner().handle) };
        match mutex.lock() {
            Ok(guard) => PooledGuard { guard },
            // A recursive process-local mutex fails only on a broken invariant
            // (`MutexProtected` panics as well).
            Err(e) => panic!("PooledArc: the mutex could not be locked: {e:?}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicU32;

    static DROPPED: AtomicU32 = AtomicU32::new(0);

    /// A size no other policy value in this test binary has, so its blocks are its own.
    #[derive(Debug)]
    struct Value([u8; 1000]);

    impl Drop for Value {
        fn drop(&mut self) {
            DROPPED.fetch_add(1, Ordering::SeqCst);
        }
    }

    impl Abandonable for Value {
        unsafe fn abandon_in_place(_this: NonNull<Self>) {}
    }

    #[test]
    fn clones_share_the_value_it_is_dropped_once_and_its_block_is_kept_for_reuse() {
        let a = PooledArc::new(Value([7; 1000])).unwrap();
        let b = a.clone();
        {
            // Recursive: iceoryx2 locks a port's state while holding a sample's.
            let outer = a.lock();
            let inner = b.lock();
            assert_eq!((outer.0[0], inner.0[999]), (7, 7));
        }
        let block = a.inner.as_ptr().cast::<u8>();
        drop(a);
        assert_eq!(DROPPED.load(Ordering::SeqCst), 0, "b still holds it");
        drop(b);
        assert_eq!(DROPPED.load(Ordering::SeqCst), 1);
        let size = PooledArc::<Value>::layout().size();
        assert_eq!(take(size), Some(block), "the block was kept, not freed");
        assert!(keep(block, size));
        let c = PooledArc::new(Value([8; 1000])).unwrap();
        assert_eq!(c.inner.as_ptr().cast::<u8>(), block, "and is reused");
        assert_eq!(c.lock().0[0], 8);
    }
}
