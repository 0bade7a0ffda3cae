"""The client side, in the trainer's interpreter: the session over the compiled module
(`session`), `Env`, `VectorEnv`, the drop-in `AsyncVectorEnv`, `make`/`make_vec`
(`factory`), the registry and adapter catalog, and the readers of what workers send
(`column_reader`, `infos`). It imports `envhub.wire` and, for the drop-in's env factories
and user adapters, the adapter contract of `envhub.worker.hosted`; never the integrations above it
(registration, SB3, recording, evaluation)."""
