"""The learned imitation controller's training: episodes on clips (:mod:`.env`), many of them in worker
processes (:mod:`.vec_env`), the clips (:mod:`.clips`), PPO in resumable chunks (:mod:`.train`). What P
runs at inference lives in :mod:`physmotion.physics.policy`."""
