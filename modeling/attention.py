"""`sdpa_varlen`: scaled dot-product attention that runs a packed row one sequence at a time.

A packed row holds several sequences back to back ([1, N], position ids restarting at each
sequence; `modeling.model.token_stats(packed=True)`). transformers' "sdpa" keeps them apart with a
dense block-diagonal [N, N] mask (masking_utils: `find_packed_sequence_indices` then `sdpa_mask`),
so the row's attention costs N^2, more than the padded batch's B * T^2 when lengths are even, and
the mask itself is N^2 booleans. `sdpa_varlen` instead runs `scaled_dot_product_attention` causally
on each sequence's slice of the row (sum of L_i^2, no mask built), as a varlen flash-attention
kernel does on GPU. Everywhere else (padded batches, left padding, generation with a KV cache, a
sliding window) it is transformers' sdpa unchanged: the same mask, the same attention call.

The sequence boundaries come from the layer's kwargs, `cu_seq_lens_q` (what `_decoder_hidden`
passes for a packed row, as flash attention reads them), or else from the position ids' restarts
(the rule transformers' own packed-sequence detection uses), so a packed row is never attended
across sequences whichever way it arrives. One difference from sdpa follows: a single row with an
all-ones 2D attention mask *and* restarting position ids attends per sequence here, where sdpa
(which looks for packing only without a mask) lets it attend across; no caller here builds one.

`use_varlen_attention(model)` switches a loaded model from "sdpa" to it (registering it with
transformers' `AttentionInterface` and `AttentionMaskInterface` first); other implementations
(flash attention, eager) are left as they are.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

SDPA_VARLEN = "sdpa_varlen"

_CODE: dict[str, object] = {}


def _masking_code() -> dict[str, object]:
    """The code objects of transformers' `and_masks` closure and packed-sequence mask closure, to
    recognise the mask `create_causal_mask` asks for on a packed row (causal AND same sequence)."""
    if not _CODE:
        from transformers import masking_utils

        _CODE["and"] = masking_utils.and_masks(masking_utils.causal_mask_function).__code__
        _CODE["packed"] = masking_utils.packed_sequence_mask_function(torch.zeros((1, 1), dtype=torch.long)).__code__
        _CODE["causal"] = masking_utils.causal_mask_function
    return _CODE


def _is_packed_causal(mask_function) -> bool:
    """Whether `mask_function` is exactly `and_masks(causal_mask_function, packed_sequence_mask_function(...))`:
    nothing else (no sliding window, chunking, image-token overlay or custom mask function)."""
    code = _masking_code()
    if getattr(mask_function, "__code__", None) is not code["and"]:
        return False
    parts = [cell.cell_contents for cell in (mask_function.__closure__ or ())
             if isinstance(cell.cell_contents, tuple)]
    if len(parts) != 1 or len(parts[0]) != 2:
        return False
    first, second = parts[0]
    return first is code["causal"] and getattr(second, "__code__", None) is code["packed"]


def sdpa_varlen_mask(batch_size: int, q_length: int, kv_length: int, q_offset=0, kv_offset=0,
                     mask_function=None, attention_mask: torch.Tensor | None = None, **kwargs):
    """transformers' `sdpa_mask`, except for one packed row of causal attention without a cache or
    padding: there no mask is built (None), and `sdpa_varlen_attention_forward` attends per sequence."""
    from transformers.masking_utils import causal_mask_function, sdpa_mask

    mask_function = causal_mask_function if mask_function is None else mask_function
    no_cache = not isinstance(q_offset, torch.Tensor) and q_offset == 0 and kv_offset == 0 and q_length == kv_length
    if (attention_mask is None and batch_size == 1 and no_cache and kwargs.get("local_size") is None
            and _is_packed_causal(mask_function)):
        return None
    return sdpa_mask(batch_size, q_length, kv_length, q_offset=q_offset, kv_offset=kv_offset,
                     mask_function=mask_function, attention_mask=attention_mask, **kwargs)


def _sequence_bounds(query: torch.Tensor, key: torch.Tensor, attention_mask, kwargs: dict) -> list[int] | None:
    """[0, L_1, L_1 + L_2, ..., N] for one packed row attended without a mask, else None (plain sdpa)."""
    if attention_mask is not None or kwargs.get("position_bias") is not None or kwargs.get("cache") is not None:
        return None
    length = query.shape[2]
    cu = kwargs.get("cu_seq_lens_q")
    if cu is not None:
        if query.shape[0] != 1 or key.shape[2] != length:
            raise ValueError(f"{SDPA_VARLEN}: cu_seq_lens_q needs one packed row without a cache; got query "
                             f"{tuple(query.shape)}, key {tuple(key.shape)}")
        bounds = [int(b) for b in cu.tolist()]
        if bounds[0] != 0 or bounds[-1] != length or any(b > a for a, b in zip(bounds[1:], bounds)):
            raise ValueError(f"{SDPA_VARLEN}: cu_seq_lens_q {bounds} must rise from 0 to the row's {length} tokens")
        return bounds
    position_ids = kwargs.get("position_ids")
    if (position_ids is None or query.shape[0] != 1 or key.shape[2] != length or length < 2
            or position_ids.shape[-1] != length or position_ids.numel() != length):
        return None
    # A sequence starts wherever the position does not follow the previous one (transformers'
    # `find_packed_sequence_indices`, which the dense mask of plain sdpa is built from).
    starts = (position_ids.reshape(-1).diff() != 1).nonzero().flatten().add(1).tolist()
    return [0, *starts, length] if starts else None


def sdpa_varlen_attention_forward(module: torch.nn.Module, query: torch.Tensor, key: torch.Tensor,
                                  value: torch.Tensor, attention_mask: torch.Tensor | None, dropout: float = 0.0,
                                  scaling: float | None = None, is_causal: bool | None = None, **kwargs):
    """Attention for `AttentionInterface`: per sequence on a packed row (`_sequence_bounds`), else
    transformers' `sdpa_attention_forward` with the same arguments."""
    from transformers.integrations.sdpa_attention import repeat_kv, sdpa_attention_forward, use_gqa_in_sdpa

    bounds = _sequence_bounds(query, key, attention_mask, kwargs)
    if bounds is None or len(bounds) <= 2:
        return sdpa_attention_forward(module, query, key, value, attention_mask, dropout=dropout, scaling=scaling,
                                      is_causal=is_causal, **kwargs)
    causal = is_causal if is_causal is not None else getattr(module, "is_causal", True)
    extra = {}
    groups = getattr(module, "num_key_value_groups", 1)
    if groups > 1:
        if use_gqa_in_sdpa(None, key, value):
            extra["enable_gqa"] = True
        else:
            key, value = repeat_kv(key, groups), repeat_kv(value, groups)
    parts = [F.scaled_dot_product_attention(query[:, :, lo:hi], key[:, :, lo:hi], value[:, :, lo:hi],
                                            dropout_p=dropout, scale=scaling, is_causal=causal and hi - lo > 1,
                                            **extra)
             for lo, hi in zip(bounds, bounds[1:]) if hi > lo]
    return torch.cat(parts, dim=2).transpose(1, 2).contiguous(), None


def register_varlen_attention() -> str:
    """Register `sdpa_varlen` with transformers (idempotent); returns its name."""
    from transformers import AttentionInterface
    from transformers.masking_utils import AttentionMaskInterface

    # The mask side must be registered too: an implementation missing from AttentionMaskInterface
    # gets no mask at all (masking_utils._preprocess_mask_arguments), which would unmask padding.
    AttentionInterface.register(SDPA_VARLEN, sdpa_varlen_attention_forward)
    AttentionMaskInterface.register(SDPA_VARLEN, sdpa_varlen_mask)
    return SDPA_VARLEN


def decoder_config(model):
    """The config the decoder's attention layers read `_attn_implementation` from (a multimodal
    wrapper's text config; the model's own config otherwise)."""
    decoder = model.get_decoder() if hasattr(model, "get_decoder") else None
    return getattr(decoder, "config", None) or model.config


def use_varlen_attention(model) -> str | None:
    """Switch `model`'s decoder from transformers' "sdpa" to `sdpa_varlen` (in place); any other
    implementation (flash attention, eager) is kept. Returns the decoder's implementation after."""
    config = decoder_config(model)
    if getattr(config, "_attn_implementation", None) == "sdpa":
        register_varlen_attention()
        config._attn_implementation = SDPA_VARLEN
    return getattr(config, "_attn_implementation", None)
