"""`flightctl diagnose`: name what the base model gets wrong in flight logs, from the logs alone.

The method (docs/diagnose.md):

1. **Equation error, one loop period ahead.** The vehicle is open-loop unstable, so the model is not
   replayed over long horizons; it predicts, from the logged commands, what the sensors show over
   each loop period: the angular acceleration (the differenced gyro, eq. 7 with the torques of eq.
   25-28 and the yaw drag of eq. 6) and the specific force (accelerometer, sum f / M along z_b). The
   command logged on row k acts until row k+1 (zero-order hold), so it is paired with the gyro
   difference between rows k and k+1 and with the accelerometer on row k+1. Measured and predicted
   channels go through the same zero-phase low-pass (their difference is filtered once), which
   takes out sensor noise without moving one against the other in time.
2. **Candidates.** Each extension of docs/measured-data.md changes the prediction; its parameters are
   fitted on a 1-D grid refined by a bounded scalar search, or by weighted linear least squares.
3. **Held-out score.** The airborne data are cut into `N_BLOCKS` contiguous blocks; for each block
   the parameters are fitted on the others and the block is predicted. `rmse_*` is the geometric
   mean over the channels of the held-out RMSE (so `1 - rmse_extended / rmse_base` is the geometric
   mean of the per-channel ratios, a Gaussian log-likelihood ratio with one variance per channel,
   which no choice of channel units can tilt).
4. **Significance.** A cause is named only if its held-out gain is at least `MIN_GAIN` and it beats
   the base model on held-out windows by `T_CRIT` standard errors; else `none`.
5. **Base model.** The paper's, plus the `[[effect]]` tables of `--params` at their parameters, each
   through its own candidate's prediction; a candidate of a carried cause is refitted in its place.

Accelerometer channels carry one constant offset each (the accelerometer bias is not calibrated
away in flight), fitted on the training blocks, for the base model and every candidate alike. The
angular channels carry none: a constant angular acceleration offset is what com_offset explains.

One module per idea, each importing only those before it:
`data` (a log -> per-file arrays and the airborne mask), `dataset` (the channels, the base
prediction, the blocks), `scoring` (held-out blocked cross-validation, significance), `candidate`
(the plug-in contract and the grid and least-squares fits), `verdict` (runs the candidates of
`flightctl.sim.causes`, names the cause, the JSON report), `report` (text and figures), `cli`.
This package module imports nothing, so that the causes can import the framework.
"""
