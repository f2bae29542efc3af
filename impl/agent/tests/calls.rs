//! Remote BICA calls between agents. In process, over the deterministic bus with hand-pumped agents and a BICA
//! runtime on a virtual clock, every step of a call is observable: the request reaches the server's agent, waits in
//! the runtime's queue until the scheduler serves it between steps, and the reply is routed to the caller by id.
//! Named errors for an unknown method, bad request bytes, an agent without runtime, a timeout and too many calls
//! in flight. Then once over RTPS on loopback, with the runtime on its own thread (`bica::Driver`).

use std::sync::Arc;
use std::time::{Duration, Instant};

use agent::{Agent, AgentConfig, AgentId, CallError, GraphId};
use bica::debug::{DebugCollector, DebugFrame, DebugPrimitive, Debuggable, Frame, Point2, Rgba, Shape};
use bica::prelude::*;
use bica::service::{COMPONENTS, ComponentsReply, DEBUG_FRAME, SET_DEBUG, Service, ServiceBuilder, SetDebug};
use bytes::Bytes;
use transport::inproc::{Bus, InProcTransport};
use transport::{Clock, ManualClock};

/// A component with a modulation (`add`) and a result (`total`), drawing a circle of its total.
#[derive(Default)]
struct Counter {
    total: i64,
    steps: u64,
}

impl Component for Counter {
    fn step(&mut self, _: &mut StepContext<'_>) -> Result<(), BicaError> {
        self.steps += 1;
        Ok(())
    }
    fn as_debuggable(&self) -> Option<&dyn Debuggable> {
        Some(self)
    }
}

impl Debuggable for Counter {
    fn debug_primitives(&self, out: &mut Vec<DebugPrimitive>) {
        let shape = Shape::Circle { center: Point2 { x: 0.0, y: 0.0 }, radius: self.total as f64 };
        out.push(DebugPrimitive::new(Frame::Robot, shape, Rgba { r: 0, g: 255, b: 0, a: 255 }));
    }
}

fn build<C: bica::Clock>(runtime: &mut Runtime<C>) -> Result<(), BicaError> {
    runtime.register(Counter::default(), 10_000_000)?;
    runtime.register(DebugCollector::new(100), 10_000_000)?;
    runtime.activate::<Counter>()?;
    runtime.activate::<DebugCollector>()
}

fn service(remote: RemoteHandle) -> Service {
    ServiceBuilder::new()
        .method("Counter.add", |counter: &mut Counter, n: i64| {
            counter.total += n;
            counter.total
        })
        .method("Counter.total", |counter: &mut Counter, (): ()| counter.total)
        .build(remote)
}

type BusAgent = Agent<InProcTransport>;

struct World {
    clock: ManualClock,
    caller: BusAgent,
    server: BusAgent,
    idle: BusAgent,
    runtime: Runtime<VirtualClock>,
}

fn world(max_calls_in_flight: usize) -> World {
    let bus = Bus::new();
    let clock = ManualClock::new(1_000_000_000);
    let agent = |id: u32| {
        let config = AgentConfig {
            max_calls_in_flight,
            nonce: Some(u64::from(id)),
            // Both start alone at once: one graph, named (each would otherwise create its own).
            graph: GraphId::new(0xca11),
            ..AgentConfig::new(AgentId(id))
        };
        Agent::new(config, bus.attach(1024), Arc::new(clock.clone()) as Arc<dyn Clock>).unwrap()
    };
    let mut runtime = Runtime::new(RuntimeConfig::default(), VirtualClock::new(0));
    build(&mut runtime).unwrap();
    let (caller, server, idle) = (agent(1), agent(2), agent(3));
    server.serve_calls(Arc::new(service(runtime.remote())));
    World { clock, caller, server, idle, runtime }
}

impl World {
    /// One round: every agent handles what it received; the runtime serves its queue and steps what is due.
    fn round(&mut self) {
        self.clock.advance(1_000_000);
        for agent in [&self.caller, &self.server, &self.idle] {
            agent.pump();
        }
        let end = bica::Clock::now_ns(self.runtime.clock()) + 1_000_000;
        self.runtime.run_until(end).unwrap();
    }

    fn call<R: serde::de::DeserializeOwned>(&mut self, to: u32, method: &str, args: Vec<u8>) -> Result<R, CallError> {
        let pending = self.caller.call_start(AgentId(to), method, Bytes::from(args))?;
        for _ in 0..5 {
            self.round();
            if let Some(reply) = pending.try_take() {
                return reply.and_then(|bytes| pending.decode(&bytes));
            }
        }
        panic!("no reply to `{method}` within 5 rounds");
    }
}

fn bytes<T: serde::Serialize>(value: &T) -> Vec<u8> {
    postcard::to_allocvec(value).unwrap()
}

#[test]
fn a_call_waits_for_the_scheduler_and_its_reply_is_routed_by_id() {
    let mut w = world(8);
    let pending = w.caller.call_start(AgentId(2), "Counter.add", Bytes::from(bytes(&5i64))).unwrap();
    // Delivered and queued, but not run: the runtime has not served its queue yet.
    w.caller.pump();
    w.server.pump();
    assert_eq!(w.runtime.registry().get::<Counter>().unwrap().total, 0);
    assert!(pending.try_take().is_none());
    // Served between steps; the reply goes out at the server's next pump and reaches the caller at its next.
    assert!(w.runtime.serve_requests());
    assert_eq!(w.runtime.registry().get::<Counter>().unwrap().total, 5);
    assert_eq!(w.server.flush_call_replies(), 1);
    w.caller.pump();
    let reply = pending.try_take().expect("the reply arrived").unwrap();
    assert_eq!(pending.decode::<i64>(&reply).unwrap(), 5);
    drop(pending);

    assert_eq!(w.call::<i64>(2, "Counter.add", bytes(&-2i64)).unwrap(), 3);
    assert_eq!(w.call::<i64>(2, "Counter.total", Vec::new()).unwrap(), 3);
    let status = w.server.status();
    assert_eq!(status.calls_served, 3);
    assert_eq!(w.caller.status().calls_in_flight, 0);
    assert_eq!(w.idle.status().calls_served, 0, "a call addressed to agent 2 reaches only agent 2");
}

#[test]
fn runtime_builtins_list_components_mark_one_and_return_its_primitives() {
    let mut w = world(8);
    let counter = std::any::type_name::<Counter>().to_owned();
    w.call::<()>(2, SET_DEBUG, bytes(&SetDebug { component: counter.clone(), on: true })).unwrap();
    w.call::<i64>(2, "Counter.add", bytes(&7i64)).unwrap();
    for _ in 0..20 {
        w.round();
    }
    let components: ComponentsReply = w.call(2, COMPONENTS, Vec::new()).unwrap();
    let names: Vec<&str> = components.statistics.components.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, [counter.as_str(), std::any::type_name::<DebugCollector>()]);
    assert_eq!(components.marked, std::slice::from_ref(&counter));
    assert!(components.statistics.components[0].counters.runs > 0);
    let frame: DebugFrame = w.call(2, DEBUG_FRAME, Vec::new()).unwrap();
    assert_eq!(frame.entries.len(), 1);
    assert_eq!(frame.entries[0].component, counter);
    assert!(matches!(frame.entries[0].primitive.shape, Shape::Circle { radius, .. } if radius == 7.0));
}

#[test]
fn unknown_methods_bad_bytes_failures_and_agents_without_runtime_are_named_errors() {
    let mut w = world(8);
    let unknown = w.call::<()>(2, "Counter.fly", Vec::new()).unwrap_err();
    assert!(matches!(&unknown, CallError::UnknownMethod { to: AgentId(2), method, .. } if method == "Counter.fly"));
    assert_eq!(unknown.to_string(), "call `Counter.fly` to agent 2: unknown method `Counter.fly`");

    let bad = w.call::<i64>(2, "Counter.add", vec![0xFF]).unwrap_err();
    assert!(matches!(bad, CallError::BadRequest { .. }), "{bad}");
    assert!(bad.to_string().starts_with("call `Counter.add` to agent 2: bad request"), "{bad}");

    let failed = w.call::<()>(2, SET_DEBUG, bytes(&SetDebug { component: "Nope".into(), on: true })).unwrap_err();
    assert!(matches!(failed, CallError::Failed { .. }), "{failed}");
    assert!(failed.to_string().contains("no component called `Nope`"), "{failed}");

    let wrong_type = w.call::<(i64, i64)>(2, "Counter.total", Vec::new()).unwrap_err();
    assert!(matches!(wrong_type, CallError::Codec { .. }), "{wrong_type}");

    let none = w.call::<i64>(3, "Counter.total", Vec::new()).unwrap_err();
    assert!(matches!(none, CallError::NoRuntime { to: AgentId(3), .. }), "{none}");
    assert!(none.to_string().contains("agent 3 serves no remote calls"), "{none}");
    assert_eq!(w.runtime.registry().get::<Counter>().unwrap().total, 0, "no failed call changed the component");
}

#[test]
fn calls_in_flight_are_bounded_and_a_late_reply_is_counted() {
    let mut w = world(2);
    // Agent 9 does not exist: these wait until given up.
    let first = w.caller.call_start(AgentId(9), "Counter.total", Bytes::new()).unwrap();
    let second = w.caller.call_start(AgentId(9), "Counter.total", Bytes::new()).unwrap();
    assert_ne!(first.id(), second.id());
    let refused = w.caller.call_start(AgentId(2), "Counter.total", Bytes::new()).unwrap_err();
    assert!(matches!(refused, CallError::TooManyInFlight { limit: 2, .. }), "{refused}");
    let timeout = first.wait(Duration::from_millis(5)).unwrap_err();
    assert_eq!(timeout.to_string(), "call `Counter.total` to agent 9: no reply within 5ms");
    assert_eq!(w.caller.status().calls_in_flight, 1);

    // A call given up before its reply arrives: the reply is counted as late and dropped.
    let given_up = w.caller.call_start(AgentId(2), "Counter.total", Bytes::new()).unwrap();
    drop(given_up);
    for _ in 0..3 {
        w.round();
    }
    assert_eq!(w.caller.status().late_call_replies, 1);
    assert_eq!(w.call::<i64>(2, "Counter.total", Vec::new()).unwrap(), 0);
    drop(second);
    assert_eq!(w.caller.status().calls_in_flight, 0);
}

/// Over RTPS on loopback: a caller agent and a serving agent whose runtime runs on its own thread.
#[test]
fn a_call_over_rtps_reaches_a_driver_runtime_and_comes_back() {
    use transport::SystemClock;
    use transport::rtps::{RtpsConfig, RtpsTransport};
    let rtps = || {
        let prefix = format!("calls{}", std::process::id());
        RtpsTransport::new(RtpsConfig { domain_id: 78, topic_prefix: prefix, ..RtpsConfig::default() }).unwrap()
    };
    let config = |id: u32| AgentConfig {
        join_wait: Duration::from_millis(200),
        graph: GraphId::new(0xca11),
        ..AgentConfig::new(AgentId(id))
    };
    let server = Agent::start(config(2), rtps(), Arc::new(SystemClock)).unwrap();
    let caller = Agent::start(config(1), rtps(), Arc::new(SystemClock)).unwrap();
    let driver = Driver::spawn(RuntimeConfig::default(), build).unwrap();
    server.serve_calls(Arc::new(service(driver.remote())));

    // Discovery: retry a cheap call until one comes back (bounded).
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        match caller.call::<(), i64>(AgentId(2), "Counter.total", &(), Duration::from_millis(200)) {
            Ok(total) => {
                assert_eq!(total, 0);
                break;
            }
            Err(CallError::Timeout { .. }) if Instant::now() < deadline => {}
            Err(error) => panic!("no call came back over RTPS: {error}"),
        }
    }
    for n in 1..=20i64 {
        let total: i64 = caller.call(AgentId(2), "Counter.add", &1i64, Duration::from_secs(5)).unwrap();
        assert_eq!(total, n);
    }
    // Round-trip latency of a small call (printed, not asserted: the machine is shared).
    let mut latencies_us: Vec<u128> = (0..300)
        .map(|_| {
            let started = Instant::now();
            let total: i64 = caller.call(AgentId(2), "Counter.total", &(), Duration::from_secs(5)).unwrap();
            assert_eq!(total, 20);
            started.elapsed().as_micros()
        })
        .collect();
    latencies_us.sort_unstable();
    let at = |q: f64| latencies_us[((latencies_us.len() - 1) as f64 * q).round() as usize];
    eprintln!(
        "call latency over RTPS loopback, 300 calls: p50 {} us, p99 {} us, max {} us",
        at(0.5),
        at(0.99),
        at(1.0)
    );
    let components: ComponentsReply = caller.call(AgentId(2), COMPONENTS, &(), Duration::from_secs(5)).unwrap();
    assert_eq!(components.statistics.components.len(), 2);
    let unknown = caller.call::<(), ()>(AgentId(2), "Counter.fly", &(), Duration::from_secs(5)).unwrap_err();
    assert!(matches!(unknown, CallError::UnknownMethod { .. }), "{unknown}");
    driver.stop().unwrap();
    // With the runtime stopped, the server answers at once that it is gone.
    let stopped = caller.call::<(), i64>(AgentId(2), "Counter.total", &(), Duration::from_secs(5)).unwrap_err();
    assert!(matches!(stopped, CallError::Busy { .. }), "{stopped}");
    caller.shutdown();
    server.shutdown();
}
