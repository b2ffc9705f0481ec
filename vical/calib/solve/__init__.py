"""The solve: the pipeline that dispatches every task (``pipeline``), the intrinsic graph (``intrinsics``), the
camera-IMU graph (``visual_inertial`` and its ``vi_*`` parts), their starts, factors, outlier screen and
uncertainty, and the judgement of a result (``plausibility``, ``model_fit``, ``uncertainty``)."""
