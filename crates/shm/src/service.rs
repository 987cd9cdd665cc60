//! The iceoryx2 service type of `sar`: iceoryx2's `ipc::Service` with every
//! shared resource in a file under the runtime directory instead of POSIX
//! shared memory in `/dev/shm`.
//!
//! `/dev/shm` is one directory for every user of the host (mode 1777): a
//! name there can be taken, truncated or filled with garbage by anyone who
//! can guess it (issue 25, findings 2 and 3). Files under the runtime
//! directory (`/run/sar`, mode 3770, the daemon's user and group) are out of
//! reach of everyone else. The runtime directory is a tmpfs under systemd
//! (`/run`), so the mappings are as fast as `/dev/shm`'s.
//!
//! iceoryx2 is built with its feature `dev_permissions` (`Cargo.toml`): its
//! files are mode 0666 and its directories 0777, so that the operators'
//! processes and the daemon (different users of one group) open each
//! other's; without it every file is its creator's alone (0600) and the
//! daemon spun on a root client's connection for a second (finding 1). The
//! runtime directory, not the modes, keeps everyone else out.

use core::fmt::Debug;
use iceoryx2_bb_elementary_traits::testing::abandonable::Abandonable;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use iceoryx2_bb_lock_free::mpmc::counting_bit_set::RelocatableCountingBitSet;
use iceoryx2_cal::event::trigger::State;
use iceoryx2_cal::event::trigger::unix_datagram_socket::GenericUnixDatagramSocketTrigger;
use iceoryx2_cal::shm_allocator::bump_allocator::BumpAllocator;
use iceoryx2_cal::shm_allocator::pool_allocator::PoolAllocator;
use iceoryx2_cal::*;

/// The service type every port of `sar` uses (in place of iceoryx2's
/// `ipc::Service`; the same parts, file-backed).
#[derive(Debug, Clone)]
pub struct Service {}

/// Dynamic storage: a file under the runtime directory.
type FileStorage<T> = dynamic_storage::file::Storage<T>;

impl iceoryx2::service::Service for Service {
    type StaticStorage = static_storage::file::Storage;
    type ConfigSerializer = serialize::recommended::Recommended;
    type PersistentDynamicStorage<T: Debug + Send + Sync + ZeroCopySend + 'static> = FileStorage<T>;
    type Bag = bag::recommended::Recommended;
    type DynamicStorage<T: Debug + Send + Sync + ZeroCopySend + 'static> = FileStorage<T>;
    type ServiceNameHasher = hash::recommended::Recommended;
    type SharedMemory = shared_memory::file::Memory<PoolAllocator>;
    type ResizableSharedMemory = resizable_shared_memory::dynamic::DynamicMemory<
        PoolAllocator,
        shared_memory::file::Memory<PoolAllocator>,
    >;
    type Connection = zero_copy_connection::file::Connection;
    type Event = GenericUnixDatagramSocketTrigger<
        RelocatableCountingBitSet,
        FileStorage<State<RelocatableCountingBitSet, ()>>,
    >;
    type Monitoring = monitoring::recommended::Ipc;
    type Reactor = reactor::recommended::Ipc;
    type ArcThreadSafetyPolicy<T: Send + Debug + Abandonable> =
        arc_sync_policy::single_threaded::SingleThreaded<T>;
    type BlackboardMgmt<KeyType: Send + Sync + Debug + ZeroCopySend + 'static> =
        FileStorage<KeyType>;
    type BlackboardPayload = shared_memory::file::Memory<BumpAllocator>;
    type UniqueId = iceoryx2::unique_id_generator::unique_system_id::UniqueSystemId;
}

impl iceoryx2::service::internal::ServiceInternal<Service> for Service {}
