"""The deployment: the one place that knows every service. The `dume` command line
(`cli`), the stack launcher (`stack`), the demo (`demo`), and beside them the files a
stack runs with: `config.toml` (deployment values), `supervisord.conf`, `zenoh/`.
"""
