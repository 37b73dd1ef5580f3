"""Other authors' methods the paper compares IPR with, reimplemented on ipr's perception.

- ``zheng2013``: Zheng et al., "Beyond point clouds: scene understanding by reasoning geometry
  and physics", CVPR 2013 (the paper's first baseline, ``ipr-shapes infer --method zheng2013``).
"""

from ipr_shapes.baselines.zheng2013 import ZhengConfig, ZhengOutcome, zheng2013

__all__ = ["ZhengConfig", "ZhengOutcome", "zheng2013"]
