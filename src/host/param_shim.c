/* PLACEHOLDER: the host's C-variadic parameter functions (owner: host helper). */
int nerfx_param_shim_placeholder(void) { return 0; }
