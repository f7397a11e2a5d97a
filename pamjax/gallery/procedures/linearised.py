"""A linearised regulator (paper 001, eq. 5-8) described in the paper's units: `flow_input` (eq. 5's Q_in as an
input of `pamjax.linearise`) and `describe` (static gains, bandwidths, poles, transfer functions). Command line:
`fits/linearise.py`; in the gallery: `p001_02_valve_model`.
"""

from pamjax.units import BAR, FLOW_UNIT


def flow_input(system):
    return system.outlet_flow  # eq. 5's Q_in [kg/s], an array leaf of `RegulatorSystem`


def describe(ss, flow=True):
    """Static gains, bandwidths, poles and transfer functions of a linearised regulator, in the paper's units."""
    num, den = ss.transfer_function("pressure", "command")
    d = dict(
        state_names=list(ss.state_names),
        input_names=list(ss.input_names),
        output_names=list(ss.output_names),
        A=ss.A.tolist(),
        B=ss.B.tolist(),
        C=ss.C.tolist(),
        D=ss.D.tolist(),
        poles_per_s=[[float(p.real), float(p.imag)] for p in ss.poles()],
        voltage_gain_bar_per_V=ss.dc_gain("pressure", "command") / BAR,
        bandwidth_Hz=ss.bandwidth("pressure", "command"),
        transfer_function_command=dict(num_Pa_per_V=num.tolist(), den=den.tolist()),
    )
    if flow:
        num_q, den_q = ss.transfer_function("pressure", "outlet_flow")
        d.update(
            flow_gain_bar_per_l_min=ss.dc_gain("pressure", "outlet_flow") * FLOW_UNIT / BAR,
            flow_bandwidth_Hz=ss.bandwidth("pressure", "outlet_flow"),
            transfer_function_outlet_flow=dict(num_Pa_per_kg_s=num_q.tolist(), den=den_q.tolist()),
        )
    return d
