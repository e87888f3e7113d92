//! A test harness for one component: placed as a host places it (its namespace, its topics),
//! fed messages by topic, ticked, finished, and what it published read back by topic, with its
//! refusals and counters. Unit tests of a node's behaviour use it instead of a running graph.
//!
//! ```
//! # use xsurf_runtime::harness::Harness;
//! # fn demo(component: Box<dyn xsurf_runtime::component::AnyComponent>, msg: xsurf_runtime::component::Msg) {
//! let mut h = Harness::new(component, "edge_detector", "/cam1");
//! h.feed("/cam1/image_raw", &msg);
//! let lines = h.take("/cam1/laser_line");
//! assert_eq!(h.errors(), 0);
//! # }
//! ```

use crate::component::{AnyComponent, Msg};
use crate::router::Router;
use std::cell::RefCell;
use std::rc::Rc;

/// One component under test.
pub struct Harness {
    router: Router,
    published: Rc<RefCell<Vec<(String, Msg)>>>,
}

impl Harness {
    /// `component` placed as `namespace/name`.
    pub fn new(component: Box<dyn AnyComponent>, name: &str, namespace: &str) -> Harness {
        let mut router = Router::new();
        router.add(component, name, namespace, &[]);
        let published: Rc<RefCell<Vec<(String, Msg)>>> = Rc::default();
        let p = published.clone();
        router.set_tap(Box::new(move |topic: &str, msg: &Msg| p.borrow_mut().push((topic.to_string(), msg.clone()))));
        Harness { router, published }
    }

    /// Delivers `msg` on `topic` (a resolved name: `/cam1/image_raw`, `/tf`).
    pub fn feed(&mut self, topic: &str, msg: &Msg) -> &mut Harness {
        self.router.publish(topic, msg);
        self
    }

    /// Ticks the component at `now_ns`.
    pub fn tick(&mut self, now_ns: i64) -> &mut Harness {
        self.router.tick(now_ns);
        self
    }

    /// Tells the component that no more input is coming.
    pub fn finish(&mut self) -> &mut Harness {
        self.router.finish();
        self
    }

    /// What the component has published on `topic` since the last `take` of it, in order.
    pub fn take(&mut self, topic: &str) -> Vec<Msg> {
        let mut all = self.published.borrow_mut();
        let (taken, kept): (Vec<_>, Vec<_>) = all.drain(..).partition(|(t, _)| t == topic);
        *all = kept;
        taken.into_iter().map(|(_, m)| m).collect()
    }

    /// Messages refused so far.
    pub fn errors(&self) -> u64 {
        self.router.nodes().first().map_or(0, |n| n.errors)
    }

    /// The last refusal, with the topic it came on.
    pub fn last_error(&self) -> Option<String> {
        self.router.nodes().first().and_then(|n| n.last_error.clone())
    }

    /// The component's counter `name`.
    pub fn counter(&self, name: &str) -> Option<u64> {
        let n = self.router.nodes().first()?;
        n.component.counters().into_iter().find(|(k, _)| *k == name).map(|(_, v)| v)
    }
}
