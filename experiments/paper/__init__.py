"""The paper's experiments, each registered by name where it is written (`@experiment`,
`registry`: the command line, the run order and the docs' index read it), and the reproduce
runner.

- `features`: trunk/wall/bush classification and a Victoria Park scan (`classification` is the
  study behind it)
- `circles`: Tables 1 and 2 (CE, RE) on the simulated pillar court, and the circle sweep
- `slam`: Tables 3 and 4 (EKF-SLAM in the simulated tree park), Figs. 7, 10, 11, consistency
- `association`: IHGR, JCBB and NN: correct-association rates and IHGR's optimality
- `calibration`: the constant measurement-noise model's fit (`noise-calibration`)
- `victoria_park`: the real run, its RFS protocol, and the derivations of its preset
- `reproduce.run_experiments`: runs them into a results folder with `manifest.json`
- `products`: figures and recordings made as trials on the executor (their files' bytes as
  records), written by the main process
"""
