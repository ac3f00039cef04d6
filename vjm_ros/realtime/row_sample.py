"""One row of a block of samples as a reusable sample, without copies (the tick loop's)."""

from __future__ import annotations

import math

from vjm_ros.sim.samples import BLOCK_FIELDS, Sample, SampleBlock


class RowSample:
    """The first row of a :class:`~vjm_ros.sim.samples.SampleBlock` as one reusable
    :class:`~vjm_ros.sim.samples.Sample` whose arrays are views of the block (no copies).

    Parameters
    ----------
    block : SampleBlock
    """

    def __init__(self, block: SampleBlock):
        self.block = block
        key_of = {attr: key for key, attr in BLOCK_FIELDS}
        scalars = ("power_in", "dissipation", "joint_loss")
        self._power, self._dissipation, self._loss = (getattr(block, key_of[a]) for a in scalars)
        views = {attr: getattr(block, key)[0] for key, attr in BLOCK_FIELDS if attr not in scalars}
        self.sample = Sample(t=0.0, effort=block.effort, power_in=0.0, dissipation=0.0,
                             joint_loss=0.0, **views)

    def refresh(self) -> Sample:
        """The sample of the tick the block holds now (valid until the next tick)."""
        s, b = self.sample, self.block
        s.t = float(b.t[0])
        s.effort = b.effort
        s.power_in = float(self._power[0])
        s.dissipation = float(self._dissipation[0])
        s.joint_loss = float(self._loss[0])
        s.sigma_min = math.nan
        s.measured = None if b.measured is None else b.measured[0]
        return s
