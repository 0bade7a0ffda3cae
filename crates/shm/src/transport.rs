//! iceoryx2 plumbing: isolated configs, service names, and the ports of one channel.
//!
//! A channel links a client to one worker: two publish/subscribe services (`…/req`,
//! `…/resp`) and an event service of the same name beside each for wake-ups. The client
//! creates all four and its own ports before the worker exists, so nothing the worker sends
//! can be lost (iceoryx2 keeps no history by default); the worker only opens them.

use crate::DataPlaneError;
use crate::layout::{BLOCK_ALIGN, RequestHeader, ResponseHeader};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::{event, publish_subscribe};
use serde::{Deserialize, Serialize};

/// The iceoryx2 service flavour: inter-process, with ports that may move between threads (a
/// client may create a session on one thread and step it on another, as Python does).
pub type Ipc = ipc_threadsafe::Service;

/// Event id meaning "a sample was published".
pub(crate) const EVENT_DATA: usize = 0;
/// Event id iceoryx2 emits when it cleans up a dead node that had a notifier.
pub(crate) const EVENT_NOTIFIER_DEAD: usize = 7;

/// Queue depth: lock-step, one request and one response in flight, plus slack.
const QUEUE_DEPTH: usize = 2;
/// Nodes per service: client, worker, and one spare (iceoryx2's cleanup, a monitor).
const MAX_NODES: usize = 3;

/// Where a channel lives: an iceoryx2 namespace (file prefix and root folder) and a name.
/// Everything a worker needs to open its channel; sent to it as JSON on its command line.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ChannelName {
    /// iceoryx2 file prefix; unique per hub namespace so parallel tests never meet.
    pub prefix: String,
    /// Base service name (`envhub/<session>/<worker>/<generation>`).
    pub service: String,
}

impl ChannelName {
    fn req(&self) -> Result<ServiceName, DataPlaneError> {
        service_name(&format!("{}/req", self.service))
    }

    fn resp(&self) -> Result<ServiceName, DataPlaneError> {
        service_name(&format!("{}/resp", self.service))
    }
}

fn iox<E: std::fmt::Debug>(what: &'static str) -> impl FnOnce(E) -> DataPlaneError {
    move |e| DataPlaneError::Ipc {
        what,
        detail: format!("{e:?}"),
    }
}

fn service_name(s: &str) -> Result<ServiceName, DataPlaneError> {
    ServiceName::new(s).map_err(iox("service name"))
}

/// An iceoryx2 config in the namespace `prefix`: its files cannot collide with another
/// namespace's, and no config file is read (so no warning about a missing one).
pub fn config(prefix: &str) -> Result<Config, DataPlaneError> {
    let mut config = Config::default();
    config.global.prefix = FileName::new(prefix.as_bytes()).map_err(iox("namespace prefix"))?;
    Ok(config)
}

/// A node in `prefix`'s namespace. Creating one also removes what dead nodes left behind.
pub fn node(prefix: &str, name: &str) -> Result<Node<Ipc>, DataPlaneError> {
    let config = config(prefix)?;
    NodeBuilder::new()
        .name(&NodeName::new(name).map_err(iox("node name"))?)
        .config(&config)
        // The process decides what Ctrl-C means; iceoryx2 must not swallow it.
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<Ipc>()
        .map_err(iox("node"))
}

/// Removes the resources of dead nodes in `prefix`'s namespace (a crashed client or worker).
pub fn cleanup_dead_nodes(prefix: &str) -> Result<(), DataPlaneError> {
    let config = config(prefix)?;
    Node::<Ipc>::list(&config, |state| {
        if let iceoryx2::node::NodeState::Dead(dead) = state {
            let _ = dead.try_remove_stale_resources();
        }
        CallbackProgression::Continue
    })
    .map_err(iox("node list"))
}

pub(crate) type ReqService = publish_subscribe::PortFactory<Ipc, [u8], RequestHeader>;
pub(crate) type RespService = publish_subscribe::PortFactory<Ipc, [u8], ResponseHeader>;
pub(crate) type EventService = event::PortFactory<Ipc>;

fn payload_alignment() -> Alignment {
    Alignment::new(BLOCK_ALIGN).expect("a power of two")
}

fn pubsub<H: std::fmt::Debug + ZeroCopySend + Default + 'static>(
    node: &Node<Ipc>,
    name: &ServiceName,
    create: bool,
) -> Result<publish_subscribe::PortFactory<Ipc, [u8], H>, DataPlaneError> {
    let builder = node
        .service_builder(name)
        .publish_subscribe::<[u8]>()
        .user_header::<H>()
        .payload_alignment(payload_alignment());
    if create {
        builder
            .max_publishers(1)
            .max_subscribers(1)
            .max_nodes(MAX_NODES)
            .history_size(0)
            .subscriber_max_buffer_size(QUEUE_DEPTH)
            // Responses are read and released at once (results live in batch slots).
            .subscriber_max_borrowed_samples(2)
            // A full queue must never drop a sample silently.
            .enable_safe_overflow(false)
            .create()
            .map_err(iox("create publish-subscribe service"))
    } else {
        builder
            .open()
            .map_err(iox("open publish-subscribe service"))
    }
}

fn events(
    node: &Node<Ipc>,
    name: &ServiceName,
    create: bool,
) -> Result<EventService, DataPlaneError> {
    let builder = node.service_builder(name).event();
    if create {
        builder
            .max_notifiers(2)
            .max_listeners(2)
            .max_nodes(MAX_NODES)
            .event_id_max_value(EVENT_NOTIFIER_DEAD)
            .notifier_dead_event(EventId::new(EVENT_NOTIFIER_DEAD))
            .create()
            .map_err(iox("create event service"))
    } else {
        builder.open().map_err(iox("open event service"))
    }
}

/// The ports of one side of a channel: publish `Out`, receive `In`, and their events.
pub(crate) struct Ports<Out: std::fmt::Debug + ZeroCopySend, In: std::fmt::Debug + ZeroCopySend> {
    /// `None` on the client until it knows the request size (see [`request_publisher`]).
    pub publisher: Option<Publisher<Ipc, [u8], Out>>,
    pub notifier: Notifier<Ipc>,
    pub subscriber: Subscriber<Ipc, [u8], In>,
    pub listener: Listener<Ipc>,
    // Services outlive the ports built from them; declared last so they drop last.
    pub services: (ReqService, RespService, EventService, EventService),
}

/// Client side: creates the services and its ports, all but the request publisher.
pub(crate) fn client_ports(
    node: &Node<Ipc>,
    name: &ChannelName,
) -> Result<Ports<RequestHeader, ResponseHeader>, DataPlaneError> {
    let (req_name, resp_name) = (name.req()?, name.resp()?);
    let req: ReqService = pubsub(node, &req_name, true)?;
    let resp: RespService = pubsub(node, &resp_name, true)?;
    let req_events = events(node, &req_name, true)?;
    let resp_events = events(node, &resp_name, true)?;
    Ok(Ports {
        publisher: None,
        notifier: req_events
            .notifier_builder()
            .default_event_id(EventId::new(EVENT_DATA))
            .create()
            .map_err(iox("request notifier"))?,
        subscriber: resp
            .subscriber_builder()
            .buffer_size(QUEUE_DEPTH)
            .create()
            .map_err(iox("response subscriber"))?,
        listener: resp_events
            .listener_builder()
            .create()
            .map_err(iox("response listener"))?,
        services: (req, resp, req_events, resp_events),
    })
}

/// The client's request publisher, made once the request size is known: a publisher whose
/// first sample outgrows its segment reallocates it, and a reallocated segment the worker never
/// mapped makes iceoryx2 warn about a lost chunk when the session closes.
pub(crate) fn request_publisher(
    service: &ReqService,
    request_bytes: usize,
) -> Result<Publisher<Ipc, [u8], RequestHeader>, DataPlaneError> {
    service
        .publisher_builder()
        .initial_max_slice_len(request_bytes.max(1))
        .allocation_strategy(AllocationStrategy::PowerOfTwo)
        .max_loaned_samples(1)
        .create()
        .map_err(iox("request publisher"))
}

/// Worker side: opens the client's services and creates its ports.
pub(crate) fn worker_ports(
    node: &Node<Ipc>,
    name: &ChannelName,
    response_bytes: usize,
) -> Result<Ports<ResponseHeader, RequestHeader>, DataPlaneError> {
    let (req_name, resp_name) = (name.req()?, name.resp()?);
    let req: ReqService = pubsub(node, &req_name, false)?;
    let resp: RespService = pubsub(node, &resp_name, false)?;
    let req_events = events(node, &req_name, false)?;
    let resp_events = events(node, &resp_name, false)?;
    Ok(Ports {
        publisher: Some(
            resp.publisher_builder()
                .initial_max_slice_len(response_bytes.max(1))
                .allocation_strategy(AllocationStrategy::PowerOfTwo)
                .max_loaned_samples(2)
                .create()
                .map_err(iox("response publisher"))?,
        ),
        notifier: resp_events
            .notifier_builder()
            .default_event_id(EventId::new(EVENT_DATA))
            .create()
            .map_err(iox("response notifier"))?,
        subscriber: req
            .subscriber_builder()
            .buffer_size(QUEUE_DEPTH)
            .create()
            .map_err(iox("request subscriber"))?,
        listener: req_events
            .listener_builder()
            .create()
            .map_err(iox("request listener"))?,
        services: (req, resp, req_events, resp_events),
    })
}

/// Removes everything a namespace left in shared memory, including iceoryx2's per-namespace
/// management file. Only for a namespace no live process uses any more (test teardown).
pub fn remove_namespace(prefix: &str) -> Result<(), DataPlaneError> {
    cleanup_dead_nodes(prefix)?;
    let config = config(prefix)?;
    let mut alive = false;
    Node::<Ipc>::list(&config, |state| {
        if matches!(state, iceoryx2::node::NodeState::Alive(_)) {
            alive = true;
        }
        CallbackProgression::Continue
    })
    .map_err(iox("node list"))?;
    if alive {
        return Err(DataPlaneError::Protocol(format!(
            "namespace `{prefix}` is still in use"
        )));
    }
    // SAFETY: no live node uses this namespace (checked above), so nothing maps the segment.
    unsafe { iceoryx2::testing::remove_global_mgmt_segment::<Ipc>(&config) }
        .map_err(iox("remove namespace"))?;
    Ok(())
}
