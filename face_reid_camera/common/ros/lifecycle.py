"""What both face-reid nodes share as ROS lifecycle nodes: parameter declaration from a :class:`ParamTable`,
the start-up walk to ACTIVE (``autostart``), throttled logging of rejected input, and ``/diagnostics``.

Logging (:meth:`ManagedNode.log`, :meth:`ManagedNode.log_throttled`) never raises, and a line marked private (names,
file paths, track/face assignments) stays in the local log (stderr and the ROS log file) of a secured node: /rosout
is a plain topic any participant of the domain reads.

Subclasses implement ``configure`` / ``activate`` / ``deactivate`` / ``cleanup`` (plain methods; an
exception in ``configure`` fails the transition with its message in :attr:`ManagedNode.failure`).

Control: a node with a network key (``network_key_path``) offers neither the standard lifecycle services
(``~/change_state`` ...) nor the parameter services (``~/set_parameters`` ...), which anyone on the DDS domain
could call; it takes transitions only through ``~/change_state_sealed`` (face_reid_msgs/ChangeState, sealed with
the key: ``face-reid-state``). Without a key the standard services stay, with a warning. A ``shutdown``
transition ends the process.
"""

from __future__ import annotations

import json
import sys
import time
import warnings
from collections.abc import Callable
from typing import Any, Literal

import rclpy.logging
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException, NameValidationException
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.lifecycle.node import LifecycleNodeMixin
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.parameter_service import ParameterService

from face_reid_camera.common.diagnostics import DiagnosticReport
from face_reid_camera.common.errors import CONFIG_EXIT_STATUS, ModelLoadError
from face_reid_camera.common.param_table import ParamError, ParamSpec, ParamTable
from face_reid_camera.common.params_files import check_ros_args, check_ros_value
from face_reid_camera.common.stamps import set_stamp
from face_reid_camera.common.transitions import QUERY, TransitionError, plan

__all__ = ["LogLevel", "ManagedNode", "descriptor_for", "fatal_start", "network_key_override", "report_to_msg",
           "run_node", "start_node"]

_TYPES = {
    "bool": Parameter.Type.BOOL, "int": Parameter.Type.INTEGER, "float": Parameter.Type.DOUBLE,
    "str": Parameter.Type.STRING, "float_list": Parameter.Type.DOUBLE_ARRAY, "str_list": Parameter.Type.STRING_ARRAY,
}
_INT64 = 2**63 - 1
LOG_THROTTLE_S = 5.0
_MAX_LOG_CHARS = 300
_DEFAULT_SEAL_AGE_S = 30.0  # a sealed transition request older (or newer) than this is refused, without max_seal_age_s
_REPLY_LINGER_S = 0.5  # after a shutdown transition, the executor spins this long so the reply reaches the caller
_LOCAL_LOGGER_SUFFIX = "local"  # <node logger>.local: not a registered sublogger, so rcl keeps it off /rosout

LogLevel = Literal["info", "warn", "error"]


def _emit(logger: Any, level: LogLevel, text: str) -> None:
    """``text`` at ``level``, from one line of code per severity: rclpy ties a call site to the severity of its
    first call and raises ValueError when the same line logs at another."""
    if level == "info":
        logger.info(text)
    elif level == "warn":
        logger.warning(text)
    else:
        logger.error(text)


def network_key_override(overrides: dict[str, Parameter[Any]]) -> str:
    """The ``network_key_path`` a node is started with (its parameter overrides: command line, params files,
    constructor), '' when none: whether the node is secured must be known before its services exist."""
    given = overrides.get("network_key_path")
    value = given.value if given is not None else ""
    return value if isinstance(value, str) else ""


def descriptor_for(spec: ParamSpec) -> ParameterDescriptor:
    """The ROS descriptor of a parameter: type, description (+ range / choices), range, read-only."""
    notes = spec.notes()
    d = ParameterDescriptor(
        name=spec.name, type=_TYPES[spec.kind].value, read_only=spec.read_only,
        description=spec.description + (f" ({notes})" if notes else ""),
        additional_constraints=spec.range_text(),
    )
    if spec.kind == "int" and (spec.low is not None or spec.high is not None):
        d.integer_range = [IntegerRange(
            from_value=int(spec.low) if spec.low is not None else -_INT64,
            to_value=int(spec.high) if spec.high is not None else _INT64, step=0)]
    elif spec.kind == "float" and (spec.low is not None or spec.high is not None):
        d.floating_point_range = [FloatingPointRange(
            from_value=float(spec.low) if spec.low is not None else -float("inf"),
            to_value=float(spec.high) if spec.high is not None else float("inf"), step=0.0)]
    return d


def report_to_msg(report: DiagnosticReport, stamp_s: float) -> DiagnosticArray:
    """A DiagnosticArray with the one status of ``report``."""
    arr = DiagnosticArray()
    set_stamp(arr.header.stamp, stamp_s)
    status = DiagnosticStatus(level=bytes([int(report.level)]), name=report.name, message=report.message,
                              hardware_id=report.hardware_id)
    status.values = [KeyValue(key=k, value=v) for k, v in report.values.items()]
    arr.status = [status]
    return arr


class ManagedNode(LifecycleNode):
    """A lifecycle node whose parameters come from one :class:`ParamTable`."""

    def __init__(self, table: ParamTable, **kwargs: Any) -> None:
        # LifecycleNode.__init__ in two steps: the node's overrides say whether it is secured, and only then are
        # the lifecycle and parameter services created (not at all when it is)
        Node.__init__(self, table.node_name, start_parameter_services=False, **kwargs)
        self.network_key_path = network_key_override(self._parameter_overrides)
        self.secured = bool(self.network_key_path)
        LifecycleNodeMixin.__init__(self, enable_communication_interface=not self.secured)
        if not self.secured:
            self._open_parameter_service = ParameterService(self)  # what Node.__init__ would have made
        self.table = table
        self.finished = False  # shut down (a shutdown transition): run_node ends the process
        self.control_requests = 0  # ~/change_state_sealed requests received
        self.control_refusals = 0  # ... of which refused (not sealed with the key for this node, replayed, not allowed)
        self._control_opener: Any = None
        self._control_sealer: Any = None  # seals this node's replies to them
        self.failure = ""  # why the last transition failed (for the FATAL line at start-up)
        self.quiet_failures = False  # run_node reports start-up failures itself, as one FATAL line
        self._configured = False
        self._active = False
        self._last_logged: dict[str, float] = {}
        # child by name only (get_child would register it with /rosout): the node's level, stderr and log file only
        self._local_logger = rclpy.logging.get_logger(f"{self.get_logger().name}.{_LOCAL_LOGGER_SUFFIX}")
        for spec in table.specs:
            try:
                self.declare_parameter(spec.name, spec.default, descriptor_for(spec))
            except InvalidParameterTypeException:  # the loader's words (ParamError), as at the start-up check
                given = self._parameter_overrides.get(spec.name)
                check_ros_value(spec, given.value if given is not None else None)
                raise ParamError(f"parameter {spec.name!r} must be a {spec.type_text()} like "
                                 f"{json.dumps(spec.default)}") from None
            except InvalidParameterValueException:  # out of the descriptor's range: the spec says so in its words
                given = self._parameter_overrides.get(spec.name)
                spec.check(given.value if given is not None else None)
                raise ParamError(f"parameter {spec.name!r} must be in {spec.range_text()}") from None
        self._warn_unknown_overrides()
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._diagnostics_pub: Any = None
        self._diagnostics_timer: Any = None
        if self.secured:
            self._offer_sealed_control()

    def warn_if_open(self) -> None:
        """The start-up warning of an unsecured node (run_node, once the node is up): who can control it."""
        if not self.secured:
            self.get_logger().warning(
                f"UNSECURED: no network_key_path: the lifecycle services ({self.get_fully_qualified_name()}/"
                "change_state ...) and parameter services (get_parameters, set_parameters ...) are open to any "
                "participant of this DDS domain: anyone can stop this node, or change and read its parameters")

    # ------------------------------------------------------------------ operator control (secured)
    def _offer_sealed_control(self) -> None:
        """``~/change_state_sealed``: transitions asked for by a holder of the network key, for this node (loaded
        now: a missing or unsafe key file stops the node from starting, ValueError); replies sealed for the
        request."""
        from face_reid_camera.common.sealing import Opener, Sealer, load_network_key
        from face_reid_msgs.srv import ChangeState

        age = float(self.get_parameter("max_seal_age_s").value) if self.has_parameter("max_seal_age_s") else (
            _DEFAULT_SEAL_AGE_S)
        key = load_network_key(self.network_key_path)
        # nothing sealed before this process started is accepted (a request captured earlier, replayed)
        self._control_opener = Opener(key, "requests", age, time.time())
        self._control_sealer = Sealer(key, self.get_fully_qualified_name(), "replies")
        self.create_service(ChangeState, "~/change_state_sealed", self._on_change_state_sealed)
        self.get_logger().info(
            "secured: no lifecycle or parameter services; transitions only through ~/change_state_sealed, sealed "
            "with the network key for this node (face-reid-state); replies sealed")

    def control_values(self) -> dict[str, object]:
        """The sealed control's counts, for the node's /diagnostics values."""
        return {"control_requests": self.control_requests, "control_refused": self.control_refusals}

    def state_label(self) -> str:
        """The current lifecycle state: unconfigured, inactive, active or finalized (or a transition state)."""
        return str(self._state_machine.current_state[1])

    def _on_change_state_sealed(self, request: Any, response: Any) -> Any:
        from face_reid_camera.common.ros.sealed import open_request, reply_is_sealed, seal_response
        from face_reid_camera.common.sealing import SealError

        self.control_requests += 1
        fqn = self.get_fully_qualified_name()
        error: SealError | None = None
        try:
            inner = open_request(self._control_opener, request, fqn, time.time())
            name = inner.transition.strip().lower()
            plan(name, self.state_label())  # refused here when not allowed from this state
            if name == QUERY:
                response.success, response.message = True, f"state {self.state_label()}"
            else:
                self.failure = ""
                done = getattr(self, f"trigger_{name}")() == TransitionCallbackReturn.SUCCESS
                response.success = done
                response.message = f"{name}: done" if done else f"{name} failed: {self.failure or 'see the log'}"
        except SealError as exc:
            error = exc
            response.success, response.message = False, f"refused: {exc}"
        except TransitionError as exc:
            response.success, response.message = False, f"refused: {exc}"
        except Exception as exc:  # a request must never take the node down
            response.success, response.message = False, f"internal error: {type(exc).__name__}: {str(exc)[:200]}"
        if response.success:
            self.get_logger().info(f"change_state_sealed: {response.message} (now {self.state_label()})")
        else:
            self.control_refusals += 1
            self.log_throttled("change_state_sealed", f"change_state_sealed: {response.message}",
                               self.control_refusals, warn=True,  # a failure's reason may name a file: private
                               private=not response.message.startswith("refused:"))
        if not reply_is_sealed(error):  # not a key holder's fresh request to this node: why, and nothing else
            return response
        response.state = self.state_label()
        return seal_response(self._control_sealer, response, fqn, request)

    # ------------------------------------------------------------------ parameters
    def _warn_unknown_overrides(self) -> None:
        known = set(self._parameters)
        self.unknown_parameters = sorted(set(self._parameter_overrides) - known)
        for name in self.unknown_parameters:
            self.get_logger().warning(
                f"parameter {name!r} given to {self.get_fully_qualified_name()} is not a parameter of this node: "
                f"ignored{self.table.suggest(name)}"
            )

    def _on_set_parameters(self, params: list[Parameter[Any]]) -> SetParametersResult:
        if not self._configured:
            return SetParametersResult(successful=True)
        return SetParametersResult(
            successful=False,
            reason="parameters are read on configure: deactivate and clean up the node, set them, configure again",
        )

    def parameter_values(self) -> dict[str, Any]:
        """Every declared parameter's current value, checked by its spec (ParamError on a bad one)."""
        return {s.name: s.check(self.get_parameter(s.name).value) for s in self.table.specs}

    # ------------------------------------------------------------------ transitions
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        try:
            self.configure()
        except Exception as exc:  # a bad parameter, a missing model, a corrupt file: say why, stay unconfigured
            self.failure = f"{exc}" if isinstance(exc, ValueError | OSError | ModelLoadError) else (
                f"{type(exc).__name__}: {exc}")
            if not self.quiet_failures:  # the reason may name a file (database, gallery): private
                self.log(f"configure failed: {self.failure}", "error", private=True)
            self._release_quietly()
            return TransitionCallbackReturn.FAILURE
        self._configured = True
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        try:
            self._diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
            self._diagnostics_timer = self.create_steady_timer(1.0, self._publish_diagnostics)
            self.activate()
            self._active = True
        except Exception as exc:
            self.failure = f"{type(exc).__name__}: {exc}"
            if not self.quiet_failures:
                self.log(f"activate failed: {self.failure}", "error", private=True)
            self._stop_diagnostics()
            return TransitionCallbackReturn.FAILURE
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._active = False
        self.deactivate()
        self._stop_diagnostics()
        return TransitionCallbackReturn.SUCCESS

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.cleanup()
        self._configured = False
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.release()
        self.finished = True  # a finalized node does nothing more: run_node ends the process
        return TransitionCallbackReturn.SUCCESS

    def release(self) -> None:
        """Undo activate and configure, whatever the state (shutdown, or the context is already gone)."""
        if self._active:
            self._active = False
            self.deactivate()
            self._stop_diagnostics()
        if self._configured:
            self._configured = False
            self.cleanup()

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._stop_diagnostics()
        self._release_quietly()
        return TransitionCallbackReturn.SUCCESS  # back to unconfigured

    def _release_quietly(self) -> None:
        try:
            self.cleanup()
        except Exception as exc:
            self.log(f"cleanup after a failure failed too: {exc}", "error", private=True)
        self._configured = False

    def _stop_diagnostics(self) -> None:
        if self._diagnostics_timer is not None:
            self.destroy_timer(self._diagnostics_timer)
            self._diagnostics_timer = None
        if self._diagnostics_pub is not None:
            self.destroy_publisher(self._diagnostics_pub)
            self._diagnostics_pub = None

    def _publish_diagnostics(self) -> None:
        pub = self._diagnostics_pub
        if pub is None:
            return
        try:
            now = self.now_s()
            pub.publish(report_to_msg(self.diagnostics(now), now))
        except Exception as exc:  # diagnostics must never take the node down
            self.log_throttled("diagnostics", f"diagnostics failed: {type(exc).__name__}: {exc}")

    # ------------------------------------------------------------------ for subclasses
    def configure(self) -> None:
        """Read parameters, load models / open files (raise to fail)."""

    def activate(self) -> None:
        """Create publishers, subscriptions and timers."""

    def deactivate(self) -> None:
        """Destroy what :meth:`activate` created."""

    def cleanup(self) -> None:
        """Release what :meth:`configure` loaded (must work after a partial configure)."""

    def diagnostics(self, now_s: float) -> DiagnosticReport:
        raise NotImplementedError

    def now_s(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def create_steady_timer(self, period_s: float, callback: Any) -> Any:
        """A timer on the monotonic clock: a wall clock stepped back does not hold it until the old future
        comes round (a ROS-time timer would stay silent for the step's length)."""
        from rclpy.clock import Clock, ClockType

        return self.create_timer(period_s, callback, clock=Clock(clock_type=ClockType.STEADY_TIME))

    @property
    def keeps_private_local(self) -> bool:
        """Whether private log lines stay off /rosout: the node has a network key (given at start, or set as a
        parameter since on an unsecured node)."""
        if self.secured:
            return True
        return self.has_parameter("network_key_path") and bool(self.get_parameter("network_key_path").value)

    def log(self, text: str, level: LogLevel = "info", private: bool = False) -> None:
        """One log line; never raises (a failed line goes to stderr). ``private``: it carries names, file paths or
        track/face assignments, so on a secured network it goes to the local log only (stderr and the ROS log
        file), not /rosout."""
        logger = self._local_logger if private and self.keeps_private_local else self.get_logger()
        try:
            _emit(logger, level, text)
        except Exception as exc:  # logging must never take the node down
            print(f"[{level.upper()}] [{logger.name}]: {text} (logging failed: {type(exc).__name__}: {exc})",
                  file=sys.stderr, flush=True)

    def log_throttled(self, key: str, message: str, total: int | None = None, warn: bool = False,
                      private: bool = False, level: LogLevel | None = None, every_s: float = LOG_THROTTLE_S) -> None:
        """Log at once the first time, then at most every ``every_s`` per key; messages are truncated. At
        ``level``, else WARN (``warn``) or ERROR; ``private`` as for :meth:`log`."""
        now = time.monotonic()
        if now - self._last_logged.get(key, -1e18) < every_s:
            return
        self._last_logged[key] = now
        text = message if len(message) <= _MAX_LOG_CHARS else message[: _MAX_LOG_CHARS - 3] + "..."
        if total is not None:
            text += f" [{key}: {total} so far]"
        self.log(text, level or ("warn" if warn else "error"), private)


def _rcl_reason(exc: Exception) -> str:
    """An RCLError's reason without rcl's source locations (", at /project/src/...")."""
    lines = str(exc).splitlines()
    return (lines[0] if lines else type(exc).__name__).split(", at /")[0][:_MAX_LOG_CHARS]


def _printed_help(argv: list[str], usage: str, table: ParamTable) -> bool:
    """--help / --help-all (before any --ros-args): the usage and the parameters printed."""
    if any(a in ("-h", "--help", "--help-all") for a in argv[1:]) and "--ros-args" not in argv:
        print(usage + table.help_text(advanced="--help-all" in argv[1:]))
        return True
    return False


def fatal_start(prog: str, message: str) -> int:
    """The one line of a node that cannot start; returns its exit status, CONFIG_EXIT_STATUS (2: face-reid-up
    does not restart it)."""
    print(f"[{prog}] FATAL: cannot start: {message}", file=sys.stderr, flush=True)
    return CONFIG_EXIT_STATUS


def start_node(prog: str, argv: list[str], make_node: Callable[[], ManagedNode]) -> ManagedNode | int:
    """rclpy started with ``argv`` and the node made; or, when either is refused (bad --ros-args, a bad parameter,
    a node name or namespace rcl refuses), one FATAL line and the exit status 2 (rclpy shut down again)."""
    import rclpy
    from rclpy.impl.implementation_singleton import rclpy_implementation

    try:
        rclpy.init(args=argv)
    except Exception as exc:  # rcl's own parser (e.g. "-p name:=" without a value): one line, not a traceback
        return fatal_start(prog, f"bad --ros-args ({type(exc).__name__}: "
                                 f"{str(exc).splitlines()[0] if str(exc) else ''}); an empty string value is written "
                                 "name:=''")
    # warnings of a node that cannot be made (rclpy: "Failed to fini rosout publisher") would follow the FATAL line
    with warnings.catch_warnings(record=True) as caught:
        try:
            node = make_node()
        except (ParamError, ValueError, NameValidationException) as exc:
            rclpy.try_shutdown()
            return fatal_start(prog, str(exc))
        except rclpy_implementation.RCLError as exc:  # rcl refused the node: e.g. a remapped name too long
            rclpy.try_shutdown()
            return fatal_start(prog, _rcl_reason(exc))
    for w in caught:  # a node that started: its warnings as they would have been shown
        warnings.showwarning(w.message, w.category, w.filename, w.lineno)
    return node


def run_node(prog: str, usage: str, table: ParamTable, make_node: Callable[[], ManagedNode],
             argv: list[str] | None = None) -> int:
    """Run a face-reid node until Ctrl-C / shutdown; returns the exit status.

    ``--help`` (without ``--ros-args``) prints ``usage`` and the deployment parameters without starting ROS
    (``--help-all``: every parameter). A bad parameter, or (with ``autostart``) a failed configure, is one
    ``FATAL`` line and exit status 2.
    """
    argv = list(sys.argv if argv is None else argv)
    if _printed_help(argv, usage, table):
        return 0
    # params files and -p settings checked by the loader replay and face-reid-up --dry-run use: one line each
    problems = check_ros_args(table, argv).problems
    for problem in problems:
        fatal_start(prog, problem)
    if problems:
        return CONFIG_EXIT_STATUS
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

    node = start_node(prog, argv, make_node)
    if isinstance(node, int):
        return node
    status = 0
    try:
        if node.get_parameter("autostart").value:
            node.quiet_failures = True
            if node.trigger_configure() != TransitionCallbackReturn.SUCCESS:
                return (status := fatal_start(prog, node.failure or "configure failed"))
            if node.trigger_activate() != TransitionCallbackReturn.SUCCESS:
                return (status := fatal_start(prog, node.failure or "activate failed"))
            node.quiet_failures = False
        node.warn_if_open()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        while rclpy.ok() and not node.finished:
            executor.spin_once(timeout_sec=0.5)
        if node.finished:  # a shutdown transition: reply to whoever asked, then end the process
            node.get_logger().info("shut down by a lifecycle transition: exiting")
            deadline = time.monotonic() + _REPLY_LINGER_S
            while rclpy.ok() and time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.05)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        try:
            if rclpy.ok() and not node.finished:
                node.trigger_shutdown()
            else:  # Ctrl-C / SIGTERM shut the context down: release without the state machine
                node.release()
        except Exception as exc:
            print(f"[{prog}] shutdown: {type(exc).__name__}: {exc}", file=sys.stderr)
        node.destroy_node()
        rclpy.try_shutdown()
    return status
