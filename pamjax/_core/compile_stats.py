"""What JAX compiles while a piece of work runs (`CompileStats`, public in `pamjax.runtime`): programs traced,
lowered and compiled, their seconds, and the persistent cache's hits."""

import threading

_PHASES = {  # jax.monitoring duration events → phase
    "/jax/core/compile/jaxpr_trace_duration": "trace",
    "/jax/core/compile/jaxpr_to_mlir_module_duration": "lower",
    "/jax/core/compile/backend_compile_duration": "compile",
}


class CompileStats:
    """What JAX compiles while active (a context manager): per phase ("trace": Python to jaxpr, "lower": jaxpr to
    StableHLO, "compile": XLA, or a persistent-cache read) the number of programs and the seconds, and of the
    persistent cache's `requests` its `hits` (`misses` = programs compiled anew); `longest_anew_s`: the longest
    compilation that was not a persistent-cache read. From `jax.monitoring`'s events. One object may be entered
    again (its numbers add up): its two listeners are registered once, while it is active, and removed when it ends
    (a JAX without `unregister_event_listener` keeps them, inactive, and the object registers no more of them).
    Before, every `with` registered two more for good: the nth use of one object counted each event n times, and
    5,000 uses slowed every later compilation down."""

    def __init__(self) -> None:
        self.count = dict.fromkeys(_PHASES.values(), 0)
        self.seconds = dict.fromkeys(_PHASES.values(), 0.0)
        self.requests = 0
        self.hits = 0
        self.longest_anew_s = 0.0
        self._active = False
        self._depth = 0  # nested `with` of this object: the listeners stay until the outermost one ends
        self._listeners = None  # (event, duration) listeners while registered
        self._hit = threading.local()  # a cache hit is recorded inside its program's compile event, in its thread

    def _event(self, event, **kwargs):
        if not self._active:
            return
        if event == "/jax/compilation_cache/compile_requests_use_cache":
            self.requests += 1
        elif event == "/jax/compilation_cache/cache_hits":
            self.hits += 1
            self._hit.pending = True

    def _duration(self, event, seconds, **kwargs):
        phase = _PHASES.get(event)
        if self._active and phase is not None:
            self.count[phase] += 1
            self.seconds[phase] += float(seconds)
            if phase == "compile":
                if getattr(self._hit, "pending", False):
                    self._hit.pending = False
                else:
                    self.longest_anew_s = max(self.longest_anew_s, float(seconds))

    @property
    def misses(self):
        return self.requests - self.hits

    def summary(self):
        return (f"traced {self.count['trace']} in {self.seconds['trace']:.1f} s, lowered {self.count['lower']} in "
                f"{self.seconds['lower']:.1f} s, compiled {self.count['compile']} in {self.seconds['compile']:.1f} s"
                + (f" ({self.hits} of {self.requests} from the persistent cache)" if self.requests else ""))

    def __enter__(self):
        import jax

        if self._listeners is None:
            self._listeners = (self._event, self._duration)
            jax.monitoring.register_event_listener(self._listeners[0])
            jax.monitoring.register_event_duration_secs_listener(self._listeners[1])
        self._depth += 1
        self._active = True
        return self

    def __exit__(self, *exc):
        import jax

        self._depth = max(self._depth - 1, 0)
        if self._depth:
            return False
        self._active = False
        event_off = getattr(jax.monitoring, "unregister_event_listener", None)
        duration_off = getattr(jax.monitoring, "unregister_event_duration_listener", None)
        if self._listeners is not None and event_off is not None and duration_off is not None:
            for off, listener in zip((event_off, duration_off), self._listeners):
                try:
                    off(listener)
                except (AssertionError, ValueError):  # already gone (jax.monitoring.clear_event_listeners())
                    pass
            self._listeners = None
        return False
