"""Units and the component names of TM-663 (Fig. 1 / Fig. 11.1). SI on the wire: N, N·m, mV."""
STANDARD_GRAVITY_M_S2 = 9.80665  # kgf -> N, as interfaces.md prescribes

# Loads in balance calibration axes and the bridge outputs that measure them, in the memo's order.
COMPONENTS = ('FX', 'FY', 'FZ', 'MX', 'MY', 'MZ')
BRIDGE_OUTPUTS = ('FXV', 'FYV', 'FZV', 'MXV', 'MYV', 'MZV')


def kgf_to_newton(value_kgf):
    """kgf (or kgf·m) to N (or N·m)."""
    return value_kgf * STANDARD_GRAVITY_M_S2
