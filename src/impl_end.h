#ifdef __cplusplus
}
#endif
#endif /* TERRAINNET_IMPLEMENTATION_DONE */
#endif /* TERRAINNET_IMPLEMENTATION */
