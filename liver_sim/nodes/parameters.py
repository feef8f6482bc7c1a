"""A node's parameters through rclpy: declared with their ranges (liver_sim.base.parameters), and every
set_parameters answered."""
from __future__ import annotations

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.exceptions import ParameterException

from liver_sim.base.parameters import Param, check_parameter


def declare_parameters(node, params: dict[str, Param]) -> dict:
    """Declare every parameter with its descriptor and range; return {name: value}.

    Out-of-range values and values outside `choices` raise ValueError naming the parameter.
    """
    values = {}
    for name, spec in params.items():
        descriptor = ParameterDescriptor(description=spec.description)
        if spec.low is not None:
            if isinstance(spec.default, int) and not isinstance(spec.default, bool):
                descriptor.integer_range = [IntegerRange(from_value=int(spec.low), to_value=int(spec.high), step=0)]
            else:
                descriptor.floating_point_range = [FloatingPointRange(from_value=float(spec.low),
                                                                      to_value=float(spec.high), step=0.0)]
        if spec.choices:
            descriptor.additional_constraints = f"one of {', '.join(map(str, spec.choices))}"
        try:
            value = node.declare_parameter(name, spec.default, descriptor).value
        except ParameterException as exc:
            raise ValueError(f"parameter {name}: {exc}") from None
        values[name] = check_parameter(name, spec, value)
    return values


def on_parameter_changes(node, params: dict[str, Param], apply) -> None:
    """Answer every set_parameters on `node`: each value is checked as at start (check_parameter), then
    `apply(changes)` ({name: value}) applies them and returns None, or returns why it refuses them all.
    The answer says what happened (logged too): never a silent success. Register after declaring."""
    def callback(parameters) -> SetParametersResult:
        changes = {}
        try:
            for parameter in parameters:
                if parameter.name not in params:
                    raise ValueError(f"{parameter.name} is not a parameter of {node.get_name()}")
                changes[parameter.name] = check_parameter(parameter.name, params[parameter.name], parameter.value)
            refused = apply(changes)
        except ValueError as exc:
            refused = str(exc)
        if refused:
            node.get_logger().warning(f"refused {changes or [p.name for p in parameters]}: {refused}")
            return SetParametersResult(successful=False, reason=refused)
        node.get_logger().info(f"applied {changes}")
        return SetParametersResult(successful=True, reason=f"applied {', '.join(changes)}")
    node.add_on_set_parameters_callback(callback)


def read_at_start(node_name: str, runtime=frozenset()):
    """An `apply` for :func:`on_parameter_changes` that refuses every name outside `runtime`: such
    parameters are read once at start."""
    def refuse(changes: dict) -> str | None:
        fixed = sorted(set(changes) - set(runtime))
        if fixed:
            return f"{', '.join(fixed)}: read at start only; restart {node_name} to change it"
        return None
    return refuse
