"""The simulated experiments and their fitting: the functional spinal unit and its range of motion (:mod:`.fsu`,
also the ``lumbar fsu`` command), the stepwise reduction (:mod:`.stepwise_reduction`), the L2-S1 cable set-up
and IDP (:mod:`.l2s1`), virtual specimens (:mod:`.virtual_experiment`), the calibration (:mod:`.calibration`), the
validation scoreboard (:mod:`.validation`) and the one registry of extra physical effects (:mod:`.effects`). See
docs/design.md."""
